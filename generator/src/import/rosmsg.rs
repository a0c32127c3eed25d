//! ROS message definitions (`.msg` text, as MCAP `ros2msg` schemas and ROS 1 bag connection
//! headers carry them) and a decoder of serialized messages into flattened numeric fields
//! (`pose.position.x`, `axes[2]`, `header.stamp.sec`).
//!
//! Two wire formats: ROS 2 CDR (XCDR1, little endian, each primitive aligned to its size relative
//! to the payload after the 4-byte encapsulation header; strings with a terminating NUL) and ROS 1
//! (packed little endian, no alignment, `time`/`duration` builtins, strings without NUL). Being
//! schema-driven, any message type is decoded, not a fixed list.

use std::collections::HashMap;

/// The serialization of a message.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Wire {
    /// ROS 2 CDR (little-endian encapsulation).
    Cdr,
    /// ROS 1 serialization.
    Ros1,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Prim {
    Bool,
    I8,
    U8,
    I16,
    U16,
    I32,
    U32,
    I64,
    U64,
    F32,
    F64,
    Str,
    /// ROS 1 `time` (u32 secs, u32 nsecs).
    Time,
    /// ROS 1 `duration` (i32 secs, i32 nsecs).
    Duration,
}

impl Prim {
    fn parse(name: &str) -> Option<Prim> {
        Some(match name {
            "bool" => Prim::Bool,
            "int8" => Prim::I8,
            "uint8" | "byte" | "char" => Prim::U8,
            "int16" => Prim::I16,
            "uint16" => Prim::U16,
            "int32" => Prim::I32,
            "uint32" => Prim::U32,
            "int64" => Prim::I64,
            "uint64" => Prim::U64,
            "float32" => Prim::F32,
            "float64" => Prim::F64,
            "string" | "wstring" => Prim::Str,
            "time" => Prim::Time,
            "duration" => Prim::Duration,
            _ => return None,
        })
    }
    fn size(self) -> usize {
        match self {
            Prim::Bool | Prim::I8 | Prim::U8 => 1,
            Prim::I16 | Prim::U16 => 2,
            Prim::I32 | Prim::U32 | Prim::F32 | Prim::Str => 4,
            Prim::I64 | Prim::U64 | Prim::F64 | Prim::Time | Prim::Duration => 8,
        }
    }
}

#[derive(Clone, Debug, PartialEq)]
enum Type {
    Prim(Prim),
    Msg(String),
}

#[derive(Clone, Copy, Debug, PartialEq)]
enum Arity {
    One,
    Fixed(usize),
    Seq,
}

#[derive(Clone, Debug, PartialEq)]
struct Field {
    name: String,
    ty: Type,
    arity: Arity,
}

/// A message type with the definitions of every type it uses.
#[derive(Clone, Debug)]
pub struct Definition {
    pub root: String,
    types: HashMap<String, Vec<Field>>,
}

/// `pkg/msg/Type` and `pkg/Type` → `pkg/Type`.
fn normal(name: &str) -> String {
    name.replace("/msg/", "/")
}

fn resolve(ty: &str, package: &str) -> String {
    if ty == "Header" {
        "std_msgs/Header".into()
    } else if ty.contains('/') {
        normal(ty)
    } else {
        format!("{package}/{ty}")
    }
}

impl Definition {
    /// Parse the concatenated definition text of `root` (its own fields first, then
    /// `MSG: pkg/Type` sections separated by `===` lines).
    pub fn parse(root: &str, text: &str) -> Result<Definition, String> {
        let root = normal(root);
        let mut types: HashMap<String, Vec<Field>> = HashMap::new();
        let mut current = root.clone();
        let mut fields = Vec::new();
        for (n, raw) in text.lines().enumerate() {
            let line = raw.split('#').next().unwrap_or("").trim();
            if line.is_empty() {
                continue;
            }
            if line.starts_with("==") {
                continue;
            }
            if let Some(name) = line.strip_prefix("MSG:") {
                types.insert(std::mem::take(&mut current), std::mem::take(&mut fields));
                current = normal(name.trim());
                continue;
            }
            let mut parts = line.split_whitespace();
            let (Some(ty), Some(name)) = (parts.next(), parts.next()) else {
                return Err(format!("line {}: `{line}` is not `type name`", n + 1));
            };
            let third = parts.next().unwrap_or("");
            if name.contains('=') || third.starts_with('=') {
                continue; // a constant
            }
            let package = current.split('/').next().unwrap_or("").to_owned();
            let (base, arity) = match ty.find('[') {
                Some(i) => {
                    let inner = ty[i + 1..].trim_end_matches(']');
                    let arity = if inner.is_empty() || inner.starts_with("<=") {
                        Arity::Seq
                    } else {
                        Arity::Fixed(
                            inner
                                .parse()
                                .map_err(|_| format!("line {}: bad array size in `{ty}`", n + 1))?,
                        )
                    };
                    (&ty[..i], arity)
                }
                None => (ty, Arity::One),
            };
            // Bounded strings: string<=10.
            let base = base.split("<=").next().unwrap_or(base);
            let ty = match Prim::parse(base) {
                Some(p) => Type::Prim(p),
                None => Type::Msg(resolve(base, &package)),
            };
            fields.push(Field {
                name: name.to_owned(),
                ty,
                arity,
            });
        }
        types.insert(current, fields);
        let def = Definition { root, types };
        def.check(&def.root, 0)?;
        Ok(def)
    }

    fn check(&self, ty: &str, depth: usize) -> Result<(), String> {
        if depth > 32 {
            return Err(format!("`{ty}` nests more than 32 levels (a recursive definition?)"));
        }
        let fields = self.types.get(ty).ok_or_else(|| format!("no definition of `{ty}`"))?;
        for f in fields {
            if let Type::Msg(m) = &f.ty {
                self.check(m, depth + 1)?;
            }
        }
        Ok(())
    }

    /// Decode one message: every numeric field (strings are skipped) is passed to `out` with its
    /// flattened name. `data` excludes nothing: for CDR it starts with the encapsulation header.
    pub fn decode(&self, wire: Wire, data: &[u8], out: &mut dyn FnMut(&str, f64)) -> Result<(), String> {
        let mut r = match wire {
            Wire::Cdr => {
                if data.len() < 4 {
                    return Err("shorter than the 4-byte CDR header".into());
                }
                if data[1] != 0x01 && data[1] != 0x03 {
                    return Err(format!(
                        "CDR encapsulation {:02x} {:02x} is not little-endian CDR",
                        data[0], data[1]
                    ));
                }
                Reader {
                    data: &data[4..],
                    pos: 0,
                    align: true,
                }
            }
            Wire::Ros1 => Reader {
                data,
                pos: 0,
                align: false,
            },
        };
        let mut name = String::new();
        self.decode_type(&self.root, wire, &mut r, &mut name, out)
    }

    fn decode_type(
        &self,
        ty: &str,
        wire: Wire,
        r: &mut Reader,
        prefix: &mut String,
        out: &mut dyn FnMut(&str, f64),
    ) -> Result<(), String> {
        let Some(fields) = self.types.get(ty) else {
            return Err(format!("no definition of `{ty}`"));
        };
        for f in fields {
            let base = prefix.len();
            if base > 0 {
                prefix.push('.');
            }
            prefix.push_str(&f.name);
            let n = match f.arity {
                Arity::One => None,
                Arity::Fixed(n) => Some(n),
                Arity::Seq => {
                    let at = r.pos;
                    Some(
                        r.u32()
                            .map_err(|_| format!("`{prefix}` at byte {at}: the message ends early"))?
                            as usize,
                    )
                }
            };
            match n {
                None => self.decode_one(&f.ty, wire, r, prefix, out)?,
                Some(n) => {
                    if n > r.data.len() {
                        return Err(format!("`{prefix}`: {n} elements announced, the message is shorter"));
                    }
                    let len = prefix.len();
                    for i in 0..n {
                        prefix.push_str(&format!("[{i}]"));
                        self.decode_one(&f.ty, wire, r, prefix, out)?;
                        prefix.truncate(len);
                    }
                }
            }
            prefix.truncate(base);
        }
        Ok(())
    }

    fn decode_one(
        &self,
        ty: &Type,
        wire: Wire,
        r: &mut Reader,
        name: &mut String,
        out: &mut dyn FnMut(&str, f64),
    ) -> Result<(), String> {
        let p = match ty {
            Type::Msg(m) => return self.decode_type(m, wire, r, name, out),
            Type::Prim(p) => *p,
        };
        let at = r.pos;
        let ends = |name: &str| format!("`{name}` at byte {at}: the message ends early");
        match p {
            Prim::Str => {
                let len = r.u32().map_err(|_| ends(name))? as usize;
                r.skip(len).map_err(|_| ends(name))?;
            }
            Prim::Time | Prim::Duration => {
                let a = r.u32().map_err(|_| ends(name))?;
                let b = r.u32().map_err(|_| ends(name))?;
                let (s, ns) = if p == Prim::Time {
                    (a as f64, b as f64)
                } else {
                    (a as i32 as f64, b as i32 as f64)
                };
                let len = name.len();
                name.push_str(".secs");
                out(name, s);
                name.truncate(len);
                name.push_str(".nsecs");
                out(name, ns);
                name.truncate(len);
            }
            _ => {
                let b = r.take(p.size()).map_err(|_| ends(name))?;
                let v = match p {
                    Prim::Bool | Prim::U8 => b[0] as f64,
                    Prim::I8 => b[0] as i8 as f64,
                    Prim::I16 => i16::from_le_bytes([b[0], b[1]]) as f64,
                    Prim::U16 => u16::from_le_bytes([b[0], b[1]]) as f64,
                    Prim::I32 => i32::from_le_bytes([b[0], b[1], b[2], b[3]]) as f64,
                    Prim::U32 => u32::from_le_bytes([b[0], b[1], b[2], b[3]]) as f64,
                    Prim::F32 => f32::from_le_bytes([b[0], b[1], b[2], b[3]]) as f64,
                    Prim::I64 => i64::from_le_bytes(b8(b)) as f64,
                    Prim::U64 => u64::from_le_bytes(b8(b)) as f64,
                    Prim::F64 => f64::from_le_bytes(b8(b)),
                    Prim::Str | Prim::Time | Prim::Duration => unreachable!(),
                };
                out(name, v);
            }
        }
        Ok(())
    }

    /// The flattened numeric field names of a message with every sequence empty (what a profile
    /// can name; sequence elements are `name[i]`).
    pub fn field_names(&self) -> Vec<String> {
        let mut out = Vec::new();
        let mut prefix = String::new();
        self.names(&self.root, &mut prefix, &mut out, 0);
        out
    }

    fn names(&self, ty: &str, prefix: &mut String, out: &mut Vec<String>, depth: usize) {
        let Some(fields) = self.types.get(ty).filter(|_| depth < 32) else {
            return;
        };
        for f in fields {
            let base = prefix.len();
            if base > 0 {
                prefix.push('.');
            }
            prefix.push_str(&f.name);
            let indices: Vec<String> = match f.arity {
                Arity::One => vec![String::new()],
                Arity::Fixed(n) => (0..n).map(|i| format!("[{i}]")).collect(),
                Arity::Seq => vec!["[i]".into()],
            };
            for idx in indices {
                let len = prefix.len();
                prefix.push_str(&idx);
                match &f.ty {
                    Type::Msg(m) => self.names(m, prefix, out, depth + 1),
                    Type::Prim(Prim::Str) => {}
                    Type::Prim(Prim::Time | Prim::Duration) => {
                        out.push(format!("{prefix}.secs"));
                        out.push(format!("{prefix}.nsecs"));
                    }
                    Type::Prim(_) => out.push(prefix.clone()),
                }
                prefix.truncate(len);
            }
            prefix.truncate(base);
        }
    }
}

fn b8(b: &[u8]) -> [u8; 8] {
    [b[0], b[1], b[2], b[3], b[4], b[5], b[6], b[7]]
}

struct Reader<'a> {
    data: &'a [u8],
    pos: usize,
    align: bool,
}

impl Reader<'_> {
    fn take(&mut self, n: usize) -> Result<&[u8], ()> {
        if self.align && n > 1 {
            let a = n.min(8);
            self.pos = self.pos.div_ceil(a) * a;
        }
        let end = self.pos.checked_add(n).ok_or(())?;
        let b = self.data.get(self.pos..end).ok_or(())?;
        self.pos = end;
        Ok(b)
    }
    fn u32(&mut self) -> Result<u32, ()> {
        let b = self.take(4)?;
        Ok(u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
    }
    fn skip(&mut self, n: usize) -> Result<(), ()> {
        let end = self.pos.checked_add(n).ok_or(())?;
        if end > self.data.len() {
            return Err(());
        }
        self.pos = end;
        Ok(())
    }
}

/// The time stamp of a decoded message's `header.stamp`, if it has one: ROS 2 `sec`/`nanosec`,
/// ROS 1 `secs`/`nsecs`.
pub fn header_stamp(fields: &HashMap<String, f64>) -> Option<f64> {
    let (s, ns) = match (fields.get("header.stamp.sec"), fields.get("header.stamp.nanosec")) {
        (Some(s), Some(ns)) => (*s, *ns),
        _ => (*fields.get("header.stamp.secs")?, *fields.get("header.stamp.nsecs")?),
    };
    Some(s + ns / 1e9)
}

#[cfg(test)]
mod tests {
    use super::*;

    const POSE: &str = "std_msgs/Header header\nPose pose\n\
        ================================================================================\n\
        MSG: geometry_msgs/Pose\nPoint position\nQuaternion orientation\n\
        ================================================================================\n\
        MSG: geometry_msgs/Point\nfloat64 x\nfloat64 y\nfloat64 z\n\
        ================================================================================\n\
        MSG: geometry_msgs/Quaternion\nfloat64 x 0\nfloat64 y 0\nfloat64 z 0\nfloat64 w 1\n\
        ================================================================================\n\
        MSG: std_msgs/Header\nbuiltin_interfaces/Time stamp\nstring frame_id\n\
        ================================================================================\n\
        MSG: builtin_interfaces/Time\nint32 sec\nuint32 nanosec\n";

    #[test]
    fn cdr_pose_stamped_by_hand() {
        let def = Definition::parse("geometry_msgs/msg/PoseStamped", POSE).unwrap();
        let mut b = vec![0u8, 1, 0, 0];
        b.extend(7i32.to_le_bytes());
        b.extend(500_000_000u32.to_le_bytes());
        b.extend(4u32.to_le_bytes());
        b.extend(b"map\0");
        // offset 16 (after the header) is 8-aligned: no padding before the doubles.
        for v in [1.0f64, 2.0, 3.0, 0.0, 0.0, 0.0, 1.0] {
            b.extend(v.to_le_bytes());
        }
        let mut got = HashMap::new();
        def.decode(Wire::Cdr, &b, &mut |n, v| {
            got.insert(n.to_owned(), v);
        })
        .unwrap();
        assert_eq!(got["pose.position.y"], 2.0);
        assert_eq!(got["pose.orientation.w"], 1.0);
        assert_eq!(header_stamp(&got), Some(7.5));
        assert!(def.field_names().contains(&"pose.orientation.w".to_owned()));
        // Cut short: an error naming the field, no panic.
        let e = def.decode(Wire::Cdr, &b[..40], &mut |_, _| {}).unwrap_err();
        assert!(e.contains("the message ends early"), "{e}");
    }

    #[test]
    fn cdr_aligns_after_odd_strings_and_reads_sequences() {
        let def = Definition::parse(
            "sensor_msgs/Joy",
            "string frame_id\nfloat32[] axes\nint32[] buttons\nuint8 FLAG=3\nfloat64 z\n",
        )
        .unwrap();
        let mut b = vec![0u8, 1, 0, 0];
        b.extend(2u32.to_le_bytes());
        b.extend(b"a\0");
        b.extend([0, 0]); // pad 6 → 8 for the sequence length
        b.extend(2u32.to_le_bytes());
        b.extend(0.5f32.to_le_bytes());
        b.extend((-1.5f32).to_le_bytes());
        b.extend(0u32.to_le_bytes()); // bytes 20..24: the double at 24 needs no padding
        b.extend(9.0f64.to_le_bytes());
        let mut got = Vec::new();
        def.decode(Wire::Cdr, &b, &mut |n, v| got.push((n.to_owned(), v)))
            .unwrap();
        assert_eq!(
            got,
            vec![("axes[0]".into(), 0.5), ("axes[1]".into(), -1.5), ("z".into(), 9.0)]
        );
    }

    #[test]
    fn ros1_is_packed_and_has_time() {
        let def = Definition::parse(
            "geometry_msgs/Vector3Stamped",
            "Header header\nVector3 vector\n===\nMSG: std_msgs/Header\nuint32 seq\ntime stamp\nstring frame_id\n\
             ===\nMSG: geometry_msgs/Vector3\nfloat64 x\nfloat64 y\nfloat64 z\n",
        )
        .unwrap();
        let mut b = Vec::new();
        b.extend(1u32.to_le_bytes());
        b.extend(3u32.to_le_bytes());
        b.extend(250_000_000u32.to_le_bytes());
        b.extend(1u32.to_le_bytes());
        b.extend(b"w");
        for v in [1.0f64, -2.0, 3.0] {
            b.extend(v.to_le_bytes());
        }
        let mut got = HashMap::new();
        def.decode(Wire::Ros1, &b, &mut |n, v| {
            got.insert(n.to_owned(), v);
        })
        .unwrap();
        assert_eq!(got["vector.y"], -2.0);
        assert_eq!(header_stamp(&got), Some(3.25));
    }

    #[test]
    fn missing_definitions_are_errors() {
        let e = Definition::parse("a/B", "c/D d\n").unwrap_err();
        assert!(e.contains("no definition of `c/D`"), "{e}");
    }
}
