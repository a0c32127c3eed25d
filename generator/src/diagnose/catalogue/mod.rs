//! The catalogue of candidate effects: each a small parametric augmentation of the model (or, for
//! `stale_samples`, of the data), named as in the model format's `corrections` block.
//!
//! With v = [vx vy vz] (world frame), T = v̇_base + g e_z the base model's thrust acceleration
//! (v̇_base its vx, vy, vz rows, evaluated with the inputs the model sees) and t the flight time:
//!
//! ```text
//! linear_drag     Δv̇ = −diag(d, d, d_z) v                               θ = (d, d_z)        1/s
//! quadratic_drag  Δv̇ = −diag(c, c, c_z) √(‖v‖² + ε²) v,  ε = 0.1 m/s    θ = (c, c_z)        1/m
//! force_bias      Δv̇ = b                                                θ = (b_x, b_y, b_z) m/s²
//! thrust_gain     Δv̇ = κ T                                              θ = κ
//! thrust_decay    Δv̇ = c t T                                            θ = c               1/s
//! ground_effect   Δv̇_z = k T_z ρ²,  ρ² = (R/4)² / (z² + (R/4)²)          θ = k (R given)
//! latency         the model sees u_j(t − d_j)                           d_j per input, s
//! actuator_lag    the model sees s_j, ṡ_j = (u_j − s_j)/τ_j             τ_j per input, s
//! channel_response the model sees k_j lag_τ(u_j(t − d_j))                 (d_j, τ_j, k_j) per input
//! loop_mismatch   rate row ℓ = gain·own_ℓ + coupling·(b_ℓ − own_ℓ)          (gain, coupling) per loop
//! stale_samples   rows repeating the previous state are treated as missing (interpolated)
//! ```
//!
//! The first six are linear in θ (fitted by least squares, [`linear`]); latency and lag act on the
//! inputs (scanned over a grid, [`inputs`]); stale samples change the data ([`crate::logs::stale`]).

pub mod inputs;
pub mod linear;
pub mod loops;

use serde::Serialize;

/// One catalogued effect.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum EffectKind {
    LinearDrag,
    QuadraticDrag,
    ForceBias,
    Latency,
    ActuatorLag,
    ChannelResponse,
    ThrustGain,
    ThrustDecay,
    GroundEffect,
    LoopMismatch,
    StaleSamples,
}

/// How an effect is fitted.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Family {
    /// Linear in its parameters: least squares on the derivative residual of vx, vy, vz.
    Linear,
    /// A transform of the inputs the model sees: a grid scan per input channel.
    Input,
    /// Delay, lag and gain of an input channel together: a 2-D scan and least squares per channel.
    Response,
    /// The base model's loops rescaled: least squares on the rate rows ([`loops`]).
    Loop,
    /// A transform of the data.
    Data,
}

impl EffectKind {
    /// Every effect, in catalogue order.
    pub const ALL: [EffectKind; 11] = [
        EffectKind::LinearDrag,
        EffectKind::QuadraticDrag,
        EffectKind::ForceBias,
        EffectKind::Latency,
        EffectKind::ActuatorLag,
        EffectKind::ChannelResponse,
        EffectKind::ThrustGain,
        EffectKind::ThrustDecay,
        EffectKind::GroundEffect,
        EffectKind::LoopMismatch,
        EffectKind::StaleSamples,
    ];

    /// The name in report.json and in the `corrections` block.
    pub fn name(self) -> &'static str {
        match self {
            EffectKind::LinearDrag => "linear_drag",
            EffectKind::QuadraticDrag => "quadratic_drag",
            EffectKind::ForceBias => "force_bias",
            EffectKind::Latency => "latency",
            EffectKind::ActuatorLag => "actuator_lag",
            EffectKind::ChannelResponse => "channel_response",
            EffectKind::ThrustGain => "thrust_gain",
            EffectKind::ThrustDecay => "thrust_decay",
            EffectKind::GroundEffect => "ground_effect",
            EffectKind::LoopMismatch => "loop_mismatch",
            EffectKind::StaleSamples => "stale_samples",
        }
    }

    /// The effect of this name.
    pub fn from_name(name: &str) -> Option<EffectKind> {
        EffectKind::ALL.into_iter().find(|e| e.name() == name)
    }

    pub fn family(self) -> Family {
        match self {
            EffectKind::Latency | EffectKind::ActuatorLag => Family::Input,
            EffectKind::StaleSamples => Family::Data,
            EffectKind::LoopMismatch => Family::Loop,
            EffectKind::ChannelResponse => Family::Response,
            _ => Family::Linear,
        }
    }

    /// What the effect stands for physically, for the report.
    pub fn meaning(self) -> &'static str {
        match self {
            EffectKind::LinearDrag => "drag proportional to velocity (rotor drag, H-force)",
            EffectKind::QuadraticDrag => "drag proportional to speed × velocity (parasitic drag)",
            EffectKind::ForceBias => "a constant force (steady wind, trim offset, c.g. offset)",
            EffectKind::Latency => "a pure delay between the command and its effect",
            EffectKind::ActuatorLag => "a first-order lag between the command and its effect",
            EffectKind::ChannelResponse => "per command channel: a delay, a first-order lag and a gain together",
            EffectKind::ThrustGain => "thrust per command scaled (payload, mass mismatch)",
            EffectKind::ThrustDecay => "thrust per command changing over the flight (battery sag)",
            EffectKind::GroundEffect => "extra lift near the ground",
            EffectKind::LoopMismatch => {
                "the aircraft's attitude or yaw loops differ from the model's (bandwidth, coupling between channels)"
            }
            EffectKind::StaleSamples => "telemetry rows that repeat the previous state (sample-and-hold)",
        }
    }
}

impl std::fmt::Display for EffectKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// The dynamic channels whose one-step residuals are analysed, in state order (states 6..12).
pub const CHANNELS: [&str; 6] = ["vx", "vy", "vz", "roll_rate", "pitch_rate", "yaw_rate"];

/// Index of the first dynamic channel in the state vector.
pub const FIRST_DYNAMIC: usize = 6;
