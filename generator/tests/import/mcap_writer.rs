//! ROS 2 messages as CDR and an MCAP file of them, for the tests: the schemas are the real
//! `ros2msg` definitions (comments and constants trimmed) of the message types MAVROS publishes.

use std::collections::BTreeMap;
use std::io::Cursor;

const SEP: &str = "================================================================================\n";

fn header_def() -> String {
    format!("{SEP}MSG: std_msgs/Header\nbuiltin_interfaces/Time stamp\nstring frame_id\n{SEP}MSG: builtin_interfaces/Time\nint32 sec\nuint32 nanosec\n")
}
fn vector3_def() -> String {
    format!("{SEP}MSG: geometry_msgs/Vector3\nfloat64 x\nfloat64 y\nfloat64 z\n")
}
fn quaternion_def() -> String {
    format!("{SEP}MSG: geometry_msgs/Quaternion\nfloat64 x 0\nfloat64 y 0\nfloat64 z 0\nfloat64 w 1\n")
}

pub fn pose_stamped() -> (&'static str, String) {
    (
        "geometry_msgs/msg/PoseStamped",
        format!(
            "std_msgs/Header header\nPose pose\n{}{SEP}MSG: geometry_msgs/Pose\nPoint position\nQuaternion orientation\n{SEP}MSG: geometry_msgs/Point\nfloat64 x\nfloat64 y\nfloat64 z\n{}",
            header_def(),
            quaternion_def()
        ),
    )
}

pub fn twist_stamped() -> (&'static str, String) {
    (
        "geometry_msgs/msg/TwistStamped",
        format!(
            "std_msgs/Header header\nTwist twist\n{}{SEP}MSG: geometry_msgs/Twist\nVector3  linear\nVector3  angular\n{}",
            header_def(),
            vector3_def()
        ),
    )
}

pub fn imu() -> (&'static str, String) {
    (
        "sensor_msgs/msg/Imu",
        format!(
            "std_msgs/Header header\ngeometry_msgs/Quaternion orientation\nfloat64[9] orientation_covariance # Row major about x, y, z axes\n\
             geometry_msgs/Vector3 angular_velocity\nfloat64[9] angular_velocity_covariance\n\
             geometry_msgs/Vector3 linear_acceleration\nfloat64[9] linear_acceleration_covariance\n{}{}{}",
            header_def(),
            quaternion_def(),
            vector3_def()
        ),
    )
}

pub fn attitude_target() -> (&'static str, String) {
    (
        "mavros_msgs/msg/AttitudeTarget",
        format!(
            "std_msgs/Header header\nuint8 IGNORE_ROLL_RATE = 1\nuint8 IGNORE_PITCH_RATE = 2\nuint8 type_mask\n\
             geometry_msgs/Quaternion orientation\ngeometry_msgs/Vector3 body_rate\nfloat32 thrust\n{}{}{}",
            header_def(),
            quaternion_def(),
            vector3_def()
        ),
    )
}

/// A CDR (XCDR1, little endian) serializer: primitives aligned to their size after the header.
pub struct Cdr(pub Vec<u8>);

impl Cdr {
    pub fn new() -> Cdr {
        Cdr(vec![0, 1, 0, 0])
    }
    fn align(&mut self, n: usize) {
        while (self.0.len() - 4) % n != 0 {
            self.0.push(0);
        }
    }
    pub fn u8(&mut self, v: u8) -> &mut Self {
        self.0.push(v);
        self
    }
    pub fn i32(&mut self, v: i32) -> &mut Self {
        self.align(4);
        self.0.extend(v.to_le_bytes());
        self
    }
    pub fn u32(&mut self, v: u32) -> &mut Self {
        self.align(4);
        self.0.extend(v.to_le_bytes());
        self
    }
    pub fn f32(&mut self, v: f32) -> &mut Self {
        self.align(4);
        self.0.extend(v.to_le_bytes());
        self
    }
    pub fn f64s(&mut self, v: &[f64]) -> &mut Self {
        for x in v {
            self.align(8);
            self.0.extend(x.to_le_bytes());
        }
        self
    }
    pub fn string(&mut self, s: &str) -> &mut Self {
        self.u32(s.len() as u32 + 1);
        self.0.extend(s.as_bytes());
        self.0.push(0);
        self
    }
    /// std_msgs/Header at `ns` nanoseconds.
    pub fn header(&mut self, ns: u64, frame: &str) -> &mut Self {
        self.i32((ns / 1_000_000_000) as i32)
            .u32((ns % 1_000_000_000) as u32)
            .string(frame)
    }
}

/// An MCAP file being written in memory.
pub struct McapFile {
    writer: mcap::Writer<Cursor<Vec<u8>>>,
    channels: BTreeMap<String, u16>,
    sequence: u32,
}

impl McapFile {
    pub fn new(compressed: bool) -> McapFile {
        let options = mcap::WriteOptions::new()
            .compression(if compressed {
                Some(mcap::Compression::Zstd)
            } else {
                None
            })
            .chunk_size(Some(64 * 1024));
        McapFile {
            writer: options.create(Cursor::new(Vec::new())).unwrap(),
            channels: BTreeMap::new(),
            sequence: 0,
        }
    }

    pub fn channel(&mut self, topic: &str, schema: (&str, String)) {
        let s = self
            .writer
            .add_schema(schema.0, "ros2msg", schema.1.as_bytes())
            .unwrap();
        let c = self.writer.add_channel(s, topic, "cdr", &BTreeMap::new()).unwrap();
        self.channels.insert(topic.to_owned(), c);
    }

    pub fn message(&mut self, topic: &str, log_ns: u64, data: &[u8]) {
        self.sequence += 1;
        let header = mcap::records::MessageHeader {
            channel_id: self.channels[topic],
            sequence: self.sequence,
            log_time: log_ns,
            publish_time: log_ns,
        };
        self.writer.write_to_known_channel(&header, data).unwrap();
    }

    pub fn finish(self) -> Vec<u8> {
        let mut writer = self.writer;
        writer.finish().unwrap();
        writer.into_inner().into_inner()
    }
}
