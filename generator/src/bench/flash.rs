//! `uavgen bench --flash`: what the crate costs a flight computer in flash and RAM.
//!
//! A minimal Cortex-M7 firmware (`thumbv7em-none-eabihf`, `target-cpu=cortex-m7`, the firmware
//! example's release profile: `opt-level = 3`, fat LTO, one codegen unit, `panic = "abort"`) holds
//! the crate's `Mpc` as a zero-initialised `static` and runs `prepare` and `feedback` in its main
//! loop, so the linker keeps exactly the solver's code. Its ELF sections are read back:
//! flash = `.vector_table` + `.text` + `.rodata` + `.data` (initial values), RAM = `.data` + `.bss` +
//! `.uninit` (the stack comes on top). The memory map is a large one (16 MiB each), so that the
//! sizes are measured whatever they are; whether they fit a given chip is the user's comparison.

use super::BenchOptions;
use object::{Object, ObjectSection};
use std::path::Path;
use std::process::Command;

/// The Cortex-M target the firmware is built for.
pub const TARGET: &str = "thumbv7em-none-eabihf";

/// Section sizes of the firmware, bytes.
#[derive(Clone, Debug, Default, PartialEq, Eq, serde::Serialize)]
pub struct FirmwareSizes {
    pub vector_table: u64,
    pub text: u64,
    pub rodata: u64,
    pub data: u64,
    pub bss: u64,
    pub uninit: u64,
}

impl FirmwareSizes {
    /// Bytes in flash: code, constants, the vector table and `.data`'s initial values.
    pub fn flash(&self) -> u64 {
        self.vector_table + self.text + self.rodata + self.data
    }

    /// Bytes of RAM without the stack.
    pub fn ram(&self) -> u64 {
        self.data + self.bss + self.uninit
    }

    /// The allocated sections of an ELF image by name (others are ignored).
    pub fn from_elf(bytes: &[u8]) -> Result<Self, String> {
        let file = object::File::parse(bytes).map_err(|e| format!("not an ELF file: {e}"))?;
        let mut s = Self::default();
        for section in file.sections() {
            let size = section.size();
            match section.name().unwrap_or("") {
                ".vector_table" => s.vector_table += size,
                ".text" => s.text += size,
                ".rodata" => s.rodata += size,
                ".data" => s.data += size,
                ".bss" => s.bss += size,
                ".uninit" => s.uninit += size,
                _ => {}
            }
        }
        if s.text == 0 {
            return Err("the firmware has no .text section".into());
        }
        Ok(s)
    }
}

const MEMORY_X: &str = "/* uavgen bench --flash: a memory map large enough for any generated solver. */
MEMORY
{
  FLASH : ORIGIN = 0x08000000, LENGTH = 16M
  RAM   : ORIGIN = 0x20000000, LENGTH = 16M
}
";

const MAIN_RS: &str = "//! uavgen bench --flash: the solver's code and state on a Cortex-M7 (sizes only, never run).
#![no_std]
#![no_main]

use core::hint::black_box;
use panic_halt as _;

#[cortex_m_rt::entry]
fn main() -> ! {
    // cortex-m-rt turns this into a `&'static mut`: the solver is a zero-initialised static (.bss).
    static mut SOLVER: solver::Mpc = solver::Mpc::new();
    let mut x = [0.0; solver::NX];
    let reference = [[0.0; solver::NX]; solver::N + 1];
    loop {
        black_box(SOLVER.prepare(black_box(&reference)));
        let solution = SOLVER.feedback(black_box(&x));
        x = solver::discrete_dynamics(&x, &black_box(solution).u0);
    }
}
";

/// Build the firmware for the crate `name` in `crate_dir` (already canonical) and read its sizes.
pub fn measure(crate_dir: &Path, name: &str, options: &BenchOptions) -> Result<FirmwareSizes, String> {
    let work = &options.work_dir;
    let dir = work.join(format!("firmware-{name}"));
    std::fs::create_dir_all(dir.join("src")).map_err(|e| format!("{}: {e}", dir.display()))?;
    let manifest = format!(
        "[package]\nname = \"uavgen-flash-{name}\"\nversion = \"0.1.0\"\nedition = \"2021\"\npublish = false\n\n\
         [dependencies]\nsolver = {{ package = \"{name}\", path = {:?} }}\n\
         cortex-m = {{ version = \"0.7\", features = [\"critical-section-single-core\"] }}\n\
         cortex-m-rt = \"0.7\"\npanic-halt = \"1\"\n\n\
         [profile.release]\npanic = \"abort\"\nopt-level = 3\nlto = true\ncodegen-units = 1\n\n[workspace]\n",
        crate_dir.display().to_string()
    );
    let write = |file: &str, text: &str| {
        let path = dir.join(file);
        std::fs::write(&path, text).map_err(|e| format!("{}: {e}", path.display()))
    };
    write("Cargo.toml", &manifest)?;
    write("memory.x", MEMORY_X)?;
    write("src/main.rs", MAIN_RS)?;
    let target_dir = work.join("target-flash");
    let rustflags = format!(
        "-C link-arg=-Tlink.x -C target-cpu=cortex-m7 -C link-arg=-L{}",
        dir.display()
    );
    let out = Command::new(std::env::var("CARGO").unwrap_or_else(|_| "cargo".into()))
        .args(["build", "--release", "--quiet", "--target", TARGET, "--manifest-path"])
        .arg(dir.join("Cargo.toml"))
        .arg("--target-dir")
        .arg(&target_dir)
        .env("RUSTFLAGS", rustflags)
        .output()
        .map_err(|e| format!("cannot run cargo: {e}"))?;
    if !out.status.success() {
        let err = String::from_utf8_lossy(&out.stderr);
        let hint = if err.contains("target may not be installed") || err.contains("can't find crate for `core`") {
            format!(" (install the target: rustup target add {TARGET})")
        } else {
            String::new()
        };
        return Err(format!(
            "building the {TARGET} firmware for {name} failed{hint}:\n{err}"
        ));
    }
    let elf = target_dir
        .join(TARGET)
        .join("release")
        .join(format!("uavgen-flash-{name}"));
    let bytes = std::fs::read(&elf).map_err(|e| format!("{}: {e}", elf.display()))?;
    FirmwareSizes::from_elf(&bytes).map_err(|e| format!("{}: {e}", elf.display()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn flash_and_ram_add_the_right_sections() {
        let s = FirmwareSizes {
            vector_table: 1,
            text: 10,
            rodata: 100,
            data: 1000,
            bss: 10000,
            uninit: 100000,
        };
        assert_eq!(s.flash(), 1111);
        assert_eq!(s.ram(), 111000);
    }

    /// This test binary is an ELF file with a .text section (on Linux); a text file is not.
    #[test]
    fn sections_are_read_from_an_elf_image() {
        let exe = std::fs::read(std::env::current_exe().unwrap()).unwrap();
        if exe.starts_with(b"\x7fELF") {
            let s = FirmwareSizes::from_elf(&exe).unwrap();
            assert!(s.text > 0);
        }
        assert!(FirmwareSizes::from_elf(b"not an object file").is_err());
    }
}
