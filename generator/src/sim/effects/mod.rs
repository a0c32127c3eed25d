//! The effects of a plant file at run time, one file each (docs/plant-format.md has the
//! equations): aerodynamic forces (drag on airspeed, the wind's direct force), the battery
//! voltage and its thrust factor, the ground effect, the command delay line, and the
//! measurement (sensor noise, sample-and-hold). The motor lag is part of the integrated state
//! (`rigid_body`), the payload of the true mass (`plant`), the wind field of `wind`.

pub mod aero;
pub mod battery;
pub mod ground;
pub mod latency;
pub mod measurement;

pub use aero::{Aero, AeroForce};
pub use battery::Battery;
pub use ground::GroundEffectModel;
pub use latency::DelayLine;
pub use measurement::Measurement;
