//! A minimal PX4 ULog writer for the tests (the format: docs.px4.io "ULog File Format"): the
//! 16-byte header, a flag-bits record, one format and one subscription per topic, data records.
//! Fields are `double` (PX4 logs `float`; double keeps the round trip exact to 1e-9) and the
//! `uint64_t timestamp` comes first.

pub struct Topic {
    pub name: String,
    /// Field declarations after the timestamp, e.g. `("q", 4)` for `double[4] q`, `("x", 0)` for a scalar.
    pub fields: Vec<(String, usize)>,
    pub multi_id: u8,
}

impl Topic {
    pub fn new(name: &str, fields: &[(&str, usize)]) -> Topic {
        Topic {
            name: name.into(),
            fields: fields.iter().map(|(n, k)| (n.to_string(), *k)).collect(),
            multi_id: 0,
        }
    }
    fn width(&self) -> usize {
        self.fields.iter().map(|(_, k)| (*k).max(1)).sum()
    }
}

pub struct ULogWriter {
    pub bytes: Vec<u8>,
    topics: Vec<Topic>,
    /// Byte offset of every data record, in write order (for corrupting tests).
    pub data_offsets: Vec<(usize, String)>,
}

fn record(out: &mut Vec<u8>, kind: u8, payload: &[u8]) {
    out.extend_from_slice(&(payload.len() as u16).to_le_bytes());
    out.push(kind);
    out.extend_from_slice(payload);
}

impl ULogWriter {
    pub fn new(topics: Vec<Topic>) -> ULogWriter {
        let mut bytes = b"ULog\x01\x12\x35".to_vec();
        bytes.push(1);
        bytes.extend_from_slice(&0u64.to_le_bytes());
        record(&mut bytes, b'B', &[0u8; 40]);
        for t in &topics {
            let mut def = format!("{}:uint64_t timestamp;", t.name);
            for (n, k) in &t.fields {
                if *k == 0 {
                    def.push_str(&format!("double {n};"));
                } else {
                    def.push_str(&format!("double[{k}] {n};"));
                }
            }
            record(&mut bytes, b'F', def.as_bytes());
        }
        let mut w = ULogWriter {
            bytes,
            topics: Vec::new(),
            data_offsets: Vec::new(),
        };
        for (id, t) in topics.iter().enumerate() {
            let mut p = vec![t.multi_id];
            p.extend_from_slice(&(id as u16).to_le_bytes());
            p.extend_from_slice(t.name.as_bytes());
            record(&mut w.bytes, b'A', &p);
        }
        w.topics = topics;
        w
    }

    /// One sample of topic `name` at `t_us` with the values in declaration order (arrays flat).
    pub fn data(&mut self, name: &str, t_us: u64, values: &[f64]) {
        let id = self.topics.iter().position(|t| t.name == name).expect("declared topic");
        assert_eq!(values.len(), self.topics[id].width(), "{name}");
        let mut p = (id as u16).to_le_bytes().to_vec();
        p.extend_from_slice(&t_us.to_le_bytes());
        for v in values {
            p.extend_from_slice(&v.to_le_bytes());
        }
        self.data_offsets.push((self.bytes.len(), name.to_owned()));
        record(&mut self.bytes, b'D', &p);
    }
}
