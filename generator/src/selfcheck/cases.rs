//! The self-check's cases: which plant effects, at which magnitude, and what `diagnose` must name.

use crate::sim::PlantFile;
use std::path::Path;

/// A plant effect (the simulator's name) and the catalogue effect that must be named for it.
pub const EFFECTS: [(&str, &str); 9] = [
    ("linear_drag", "linear_drag"),
    ("quadratic_drag", "quadratic_drag"),
    ("wind", "force_bias"),
    ("motor_lag", "actuator_lag"),
    ("latency", "latency"),
    ("payload", "thrust_gain"),
    ("battery_sag", "thrust_decay"),
    ("ground_effect", "ground_effect"),
    ("sample_hold", "stale_samples"),
];

/// The catalogue name for a plant effect.
pub fn expected(plant_effect: &str) -> Option<&'static str> {
    EFFECTS.iter().find(|(p, _)| *p == plant_effect).map(|(_, c)| *c)
}

/// How strong an effect is in a case.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Magnitude {
    /// The value in `plants/effects/<name>.json`.
    Realistic,
    /// That value scaled by this factor (ground effect: its thrust-ratio cap 1 + f·(cap − 1)).
    Small(f64),
}

/// One case: the plant effects switched on (none: fresh nominal logs).
#[derive(Clone, Debug, PartialEq)]
pub struct Case {
    pub effects: Vec<&'static str>,
    pub magnitude: Magnitude,
}

impl Case {
    pub fn name(&self) -> String {
        if self.effects.is_empty() {
            return "nominal".into();
        }
        let m = match self.magnitude {
            Magnitude::Realistic => "realistic".to_string(),
            Magnitude::Small(f) => format!("small ×{f}"),
        };
        format!("{} ({m})", self.effects.join(" + "))
    }

    /// The catalogue names that must appear in the verdict (`["none"]` for nominal).
    pub fn truth(&self) -> Vec<String> {
        if self.effects.is_empty() {
            return vec!["none".into()];
        }
        self.effects
            .iter()
            .filter_map(|e| expected(e))
            .map(String::from)
            .collect()
    }

    /// `base` with this case's effects from `plants/effects/<name>.json`, scaled.
    pub fn plant(&self, base: &PlantFile, plants: &Path) -> Result<PlantFile, String> {
        let mut p = base.clone();
        for name in &self.effects {
            let path = plants.join("effects").join(format!("{name}.json"));
            let one = PlantFile::load(&path).map_err(|e| e.to_string())?;
            let mut e = one.effects;
            if let Magnitude::Small(f) = self.magnitude {
                scale(&mut e, f);
            }
            let fx = &mut p.effects;
            match *name {
                "linear_drag" => fx.linear_drag = e.linear_drag,
                "quadratic_drag" => fx.quadratic_drag = e.quadratic_drag,
                "wind" => fx.wind = e.wind,
                "motor_lag" => fx.motor_lag = e.motor_lag,
                "latency" => fx.latency = e.latency,
                "payload" => fx.payload = e.payload,
                "battery_sag" => fx.battery_sag = e.battery_sag,
                "ground_effect" => fx.ground_effect = e.ground_effect,
                "sample_hold" => fx.sample_hold = e.sample_hold,
                other => return Err(format!("self-check: unknown plant effect '{other}'")),
            }
        }
        p.validate().map_err(|e| e.to_string())?;
        Ok(p)
    }
}

/// Scale every effect's magnitude by `f`.
fn scale(e: &mut crate::sim::plant_file::Effects, f: f64) {
    if let Some(d) = &mut e.linear_drag {
        d.coefficients.iter_mut().for_each(|c| *c *= f);
    }
    if let Some(d) = &mut e.quadratic_drag {
        d.coefficients.iter_mut().for_each(|c| *c *= f);
    }
    if let Some(w) = &mut e.wind {
        w.velocity.iter_mut().for_each(|c| *c *= f);
        if let Some(t) = &mut w.turbulence {
            t.sigma.iter_mut().for_each(|c| *c *= f);
        }
    }
    if let Some(m) = &mut e.motor_lag {
        m.time_constant *= f;
    }
    if let Some(l) = &mut e.latency {
        l.delay = l.delay.map(|d| d * f);
        if let Some(c) = &mut l.per_channel {
            c.iter_mut().for_each(|d| *d *= f);
        }
    }
    if let Some(p) = &mut e.payload {
        p.mass *= f;
    }
    if let Some(b) = &mut e.battery_sag {
        b.rate *= f;
    }
    if let Some(g) = &mut e.ground_effect {
        g.max_ratio = 1.0 + f * (g.max_ratio - 1.0);
    }
    if let Some(s) = &mut e.sample_hold {
        s.probability *= f;
    }
}

/// Every effect at realistic and small (×0.3) magnitude, three pairs, and fresh nominal logs.
pub fn default_cases() -> Vec<Case> {
    let mut cases = Vec::new();
    for magnitude in [Magnitude::Realistic, Magnitude::Small(0.3)] {
        for (e, _) in EFFECTS {
            cases.push(Case {
                effects: vec![e],
                magnitude,
            });
        }
    }
    for pair in [
        ["linear_drag", "latency"],
        ["payload", "ground_effect"],
        ["wind", "motor_lag"],
    ] {
        cases.push(Case {
            effects: pair.to_vec(),
            magnitude: Magnitude::Realistic,
        });
    }
    cases.push(Case {
        effects: Vec::new(),
        magnitude: Magnitude::Realistic,
    });
    cases
}

/// The reduced set CI runs: every effect at realistic magnitude, one pair, nominal.
pub fn reduced_cases() -> Vec<Case> {
    let mut cases: Vec<Case> = EFFECTS
        .iter()
        .map(|(e, _)| Case {
            effects: vec![*e],
            magnitude: Magnitude::Realistic,
        })
        .collect();
    cases.push(Case {
        effects: vec!["linear_drag", "latency"],
        magnitude: Magnitude::Realistic,
    });
    cases.push(Case {
        effects: Vec::new(),
        magnitude: Magnitude::Realistic,
    });
    cases
}
