//! A minimal ArduPilot DataFlash writer for the tests: FMT records (the FMT of FMT first, as the
//! autopilot writes it), then data records `A3 95 type payload`. Fields here are `Q` (TimeUS),
//! `B` (instance) and `d` (double; ArduPilot logs many as `f` or hundredths, doubles keep the
//! round trip exact to 1e-9).

pub struct DataFlashWriter {
    pub bytes: Vec<u8>,
    types: Vec<(String, u8, String)>,
    /// Byte offset of every data record with its message name.
    pub offsets: Vec<(usize, String)>,
}

fn padded(s: &str, n: usize) -> Vec<u8> {
    let mut v = s.as_bytes().to_vec();
    v.resize(n, 0);
    v
}

fn size(c: char) -> usize {
    match c {
        'B' => 1,
        'Q' | 'd' => 8,
        _ => panic!("writer supports Q B d"),
    }
}

impl DataFlashWriter {
    pub fn new() -> DataFlashWriter {
        let mut w = DataFlashWriter {
            bytes: Vec::new(),
            types: Vec::new(),
            offsets: Vec::new(),
        };
        w.fmt(0x80, "FMT", 89, "BBnNZ", "Type,Length,Name,Format,Labels");
        w
    }

    fn fmt(&mut self, ty: u8, name: &str, len: usize, format: &str, labels: &str) {
        self.bytes.extend([0xA3, 0x95, 0x80, ty, len as u8]);
        self.bytes.extend(padded(name, 4));
        self.bytes.extend(padded(format, 16));
        self.bytes.extend(padded(labels, 64));
    }

    /// Declare message `name` with `format` (Q B d only) and comma-separated `labels`.
    pub fn message_type(&mut self, name: &str, format: &str, labels: &str) {
        let ty = 100 + self.types.len() as u8;
        let len = 3 + format.chars().map(size).sum::<usize>();
        self.fmt(ty, name, len, format, labels);
        self.types.push((name.into(), ty, format.into()));
    }

    /// One record: TimeUS, then the other fields in order (B as f64 0..255).
    pub fn write(&mut self, name: &str, time_us: u64, values: &[f64]) {
        let (_, ty, format) = self.types.iter().find(|t| t.0 == name).expect("declared").clone();
        assert_eq!(format.len(), values.len() + 1, "{name}");
        self.offsets.push((self.bytes.len(), name.to_owned()));
        self.bytes.extend([0xA3, 0x95, ty]);
        self.bytes.extend(time_us.to_le_bytes());
        for (c, v) in format.chars().skip(1).zip(values) {
            match c {
                'B' => self.bytes.push(*v as u8),
                'd' => self.bytes.extend(v.to_le_bytes()),
                'Q' => self.bytes.extend((*v as u64).to_le_bytes()),
                _ => unreachable!(),
            }
        }
    }
}
