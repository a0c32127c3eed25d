//! A plant simulator: a rigid-body quadrotor of Matrice-100 size behind an emulated DJI-SDK
//! autopilot (commands u = [u_vz, u_roll, u_pitch, u_yaw_rate]), with optional effects (drag,
//! wind, motor lag, latency, payload, battery sag, ground effect, sensor noise, stale samples),
//! integrated by RK4 at a fine rate and sampled into LOG_FORMAT.md logs. See
//! `docs/plant-format.md` (the plant file, the equations) and `docs/simulate.md` (the command,
//! the profiles).
//!
//! ```no_run
//! use uavgen::sim::{simulate, Plant, PlantFile, Profile, SimulateOptions};
//! let file = PlantFile::load("plants/nominal.json".as_ref()).unwrap();
//! // A closed loop of one's own:
//! let mut plant = Plant::new(&file, 7);
//! plant.reset(&[3.0, 3.0, 5.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]);
//! for _ in 0..300 {
//!     let y = plant.measured();
//!     plant.step(&[0.5 * (5.0 - y[2]), 0.0, 0.0, 0.0]);
//! }
//! // Or a whole log:
//! let opts = SimulateOptions::new(vec![Profile::Excite, Profile::Circle], vec![60.0, 30.0], 7);
//! simulate(&file, &opts).unwrap().write("log.csv".as_ref()).unwrap();
//! ```

pub mod autopilot;
pub mod effects;
pub mod error;
pub mod log_writer;
pub mod outer_loop;
pub mod plant;
pub mod plant_file;
pub mod profiles;
pub mod rigid_body;
pub mod rng;
pub mod run;
pub mod wind;

pub use error::{PlantError, PlantErrorKind};
pub use log_writer::write_atomically;
pub use plant::{wrap_angle, Plant, PlantStats};
pub use plant_file::{PlantFile, EFFECT_NAMES, PAPER_INPUT_LIMITS, PLANT_FORMAT};
pub use profiles::Profile;
pub use run::{simulate, LogRow, SegmentSummary, SimulateOptions, SimulatedLog};
