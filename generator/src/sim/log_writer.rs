//! The simulated log as LOG_FORMAT.md CSV (version 1), written atomically.
//!
//! `# key: value` metadata lines, the header
//! `t,x,y,z,roll,pitch,yaw,vx,vy,vz,roll_rate,pitch_rate,yaw_rate,u_vz,u_roll,u_pitch,u_yaw_rate,battery_voltage,segment`,
//! one row per sample: numbers with 6 decimals, yaw wrapped to (−π, π], −0 written as 0.

use super::error::{PlantError, PlantErrorKind};
use super::plant::wrap_angle;
use super::run::SimulatedLog;
use std::fmt::Write as _;
use std::path::Path;

/// The header row.
pub const HEADER: &str = "t,x,y,z,roll,pitch,yaw,vx,vy,vz,roll_rate,pitch_rate,yaw_rate,\
u_vz,u_roll,u_pitch,u_yaw_rate,battery_voltage,segment";

fn number(out: &mut String, v: f64) {
    let start = out.len();
    let _ = write!(out, "{v:.6}");
    if out[start..].bytes().all(|b| matches!(b, b'-' | b'0' | b'.')) && out.as_bytes()[start] == b'-' {
        out.remove(start);
    }
}

impl SimulatedLog {
    /// The CSV text.
    pub fn to_csv(&self) -> String {
        let mut out = String::with_capacity(self.rows.len() * 190 + 1024);
        for (k, v) in &self.metadata {
            let _ = writeln!(out, "# {k}: {v}");
        }
        out.push_str(HEADER);
        out.push('\n');
        for r in &self.rows {
            number(&mut out, r.t);
            for (i, v) in r.x.iter().enumerate() {
                out.push(',');
                number(&mut out, if i == 5 { wrap_angle(*v) } else { *v });
            }
            for v in r.u {
                out.push(',');
                number(&mut out, v);
            }
            out.push(',');
            number(&mut out, r.battery_voltage);
            let _ = writeln!(out, ",{}", r.segment);
        }
        out
    }

    /// Write the CSV to `path` atomically: a temporary file in the same directory, then a
    /// rename, so a failure leaves no partial file (and an existing file untouched).
    pub fn write(&self, path: &Path) -> Result<(), PlantError> {
        write_atomically(path, &self.to_csv())
    }
}

/// Write `text` to `path` through a temporary file in the same directory and a rename.
pub fn write_atomically(path: &Path, text: &str) -> Result<(), PlantError> {
    let label = path.display().to_string();
    let name = path
        .file_name()
        .ok_or_else(|| PlantError::new(&label, "", PlantErrorKind::Write, "not a file path"))?;
    let mut tmp_name = std::ffi::OsString::from(".");
    tmp_name.push(name);
    tmp_name.push(format!(".{}.uavgen-tmp", std::process::id()));
    let tmp = path.with_file_name(tmp_name);
    // One critical section: an interrupting signal waits for it (crate::interrupt).
    let _guard = crate::interrupt::output_lock();
    // What a killed run left beside this output: its temporary carries its dead pid.
    let dir = match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    };
    crate::interrupt::remove_stale(dir, &format!(".{}.", name.to_string_lossy()), ".uavgen-tmp");
    let fail = |e: std::io::Error| PlantError::new(&label, "", PlantErrorKind::Write, format!("cannot write: {e}"));
    if let Err(e) = std::fs::write(&tmp, text) {
        let _ = std::fs::remove_file(&tmp);
        return Err(fail(e));
    }
    std::fs::rename(&tmp, path).map_err(|e| {
        let _ = std::fs::remove_file(&tmp);
        fail(e)
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn numbers_have_six_decimals_and_no_negative_zero() {
        let mut s = String::new();
        for v in [-0.0, -1e-9, 1.5, -2.25, 1234.0000004] {
            number(&mut s, v);
            s.push(' ');
        }
        assert_eq!(s, "0.000000 0.000000 1.500000 -2.250000 1234.000000 ");
    }

    #[test]
    fn failed_write_leaves_nothing() {
        let dir = tempfile::tempdir().unwrap();
        let missing = dir.path().join("no/such/dir/log.csv");
        assert!(write_atomically(&missing, "x").is_err());
        let target = dir.path().join("log.csv");
        write_atomically(&target, "a,b\n").unwrap();
        assert_eq!(std::fs::read_to_string(&target).unwrap(), "a,b\n");
        // Only log.csv: no temporary file is left behind.
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1);
    }
}
