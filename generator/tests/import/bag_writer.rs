//! A minimal ROS 1 bag (format 2.0) writer for the tests: the bag header record, then uncompressed
//! chunks holding connection and message-data records (no index section, like a bag whose recorder
//! was stopped before writing it). ROS 1 serialization: packed little endian, `time` as two u32.

pub const SEP: &str = "================================================================================\n";

pub fn header_def() -> String {
    format!("{SEP}MSG: std_msgs/Header\nuint32 seq\ntime stamp\nstring frame_id\n")
}

fn field(out: &mut Vec<u8>, name: &str, value: &[u8]) {
    out.extend(((name.len() + 1 + value.len()) as u32).to_le_bytes());
    out.extend(name.as_bytes());
    out.push(b'=');
    out.extend(value);
}

fn record(out: &mut Vec<u8>, header: &[(&str, Vec<u8>)], data: &[u8]) {
    let mut h = Vec::new();
    for (n, v) in header {
        field(&mut h, n, v);
    }
    out.extend((h.len() as u32).to_le_bytes());
    out.extend(h);
    out.extend((data.len() as u32).to_le_bytes());
    out.extend(data);
}

/// ROS 1 message bytes.
#[derive(Default)]
pub struct Ros1(pub Vec<u8>);

impl Ros1 {
    pub fn header(&mut self, seq: u32, ns: u64, frame: &str) -> &mut Self {
        self.0.extend(seq.to_le_bytes());
        self.0.extend(((ns / 1_000_000_000) as u32).to_le_bytes());
        self.0.extend(((ns % 1_000_000_000) as u32).to_le_bytes());
        self.0.extend((frame.len() as u32).to_le_bytes());
        self.0.extend(frame.as_bytes());
        self
    }
    pub fn f64s(&mut self, v: &[f64]) -> &mut Self {
        v.iter().for_each(|x| self.0.extend(x.to_le_bytes()));
        self
    }
    pub fn f32_seq(&mut self, v: &[f32]) -> &mut Self {
        self.0.extend((v.len() as u32).to_le_bytes());
        v.iter().for_each(|x| self.0.extend(x.to_le_bytes()));
        self
    }
    pub fn i32_seq(&mut self, v: &[i32]) -> &mut Self {
        self.0.extend((v.len() as u32).to_le_bytes());
        v.iter().for_each(|x| self.0.extend(x.to_le_bytes()));
        self
    }
}

pub struct BagWriter {
    pub bytes: Vec<u8>,
    chunk: Vec<u8>,
    connections: Vec<(String, String, String)>,
    /// Byte offset of every chunk record.
    pub chunk_offsets: Vec<usize>,
    pub compression: &'static str,
}

impl BagWriter {
    pub fn new() -> BagWriter {
        let mut bytes = b"#ROSBAG V2.0\n".to_vec();
        record(
            &mut bytes,
            &[
                ("op", vec![0x03]),
                ("index_pos", 0u64.to_le_bytes().to_vec()),
                ("conn_count", 0u32.to_le_bytes().to_vec()),
                ("chunk_count", 0u32.to_le_bytes().to_vec()),
            ],
            &[b' '; 64],
        );
        BagWriter {
            bytes,
            chunk: Vec::new(),
            connections: Vec::new(),
            chunk_offsets: Vec::new(),
            compression: "none",
        }
    }

    /// Declare a topic of `ty` with its full message definition.
    pub fn connection(&mut self, topic: &str, ty: &str, definition: &str) {
        let id = self.connections.len() as u32;
        let mut data = Vec::new();
        field(&mut data, "topic", topic.as_bytes());
        field(&mut data, "type", ty.as_bytes());
        field(&mut data, "md5sum", b"*");
        field(&mut data, "message_definition", definition.as_bytes());
        record(
            &mut self.chunk,
            &[
                ("op", vec![0x07]),
                ("conn", id.to_le_bytes().to_vec()),
                ("topic", topic.as_bytes().to_vec()),
            ],
            &data,
        );
        self.connections.push((topic.into(), ty.into(), definition.into()));
    }

    pub fn message(&mut self, topic: &str, receive_ns: u64, data: &[u8]) {
        let id = self.connections.iter().position(|c| c.0 == topic).expect("declared") as u32;
        let mut time = ((receive_ns / 1_000_000_000) as u32).to_le_bytes().to_vec();
        time.extend(((receive_ns % 1_000_000_000) as u32).to_le_bytes());
        record(
            &mut self.chunk,
            &[("op", vec![0x02]), ("conn", id.to_le_bytes().to_vec()), ("time", time)],
            data,
        );
    }

    /// Close the current chunk.
    pub fn flush(&mut self) {
        if self.chunk.is_empty() {
            return;
        }
        self.chunk_offsets.push(self.bytes.len());
        let chunk = std::mem::take(&mut self.chunk);
        record(
            &mut self.bytes,
            &[
                ("op", vec![0x05]),
                ("compression", self.compression.as_bytes().to_vec()),
                ("size", (chunk.len() as u32).to_le_bytes().to_vec()),
            ],
            &chunk,
        );
    }

    pub fn finish(mut self) -> Vec<u8> {
        self.flush();
        self.bytes
    }
}
