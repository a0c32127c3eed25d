//! Every invalid `corrections` block gives a located error: the file, the JSON path and the
//! problem (docs/model-format.md#corrections).

use serde_json::{json, Value};
use uavgen::model::{parse, ModelErrorKind};

fn sindy() -> Value {
    json!({
        "format": "uavgen-model/1", "kind": "sindy", "name": "toy",
        "library": ["u_vz"],
        "kinematic": [["z", "vz"]],
        "coefficients": [{"state": "vz", "term": "u_vz", "coefficient": 2.0}]
    })
}

fn pd() -> Value {
    let text = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/../models/pd_hover.json")).unwrap();
    serde_json::from_str(&text).unwrap()
}

/// The error message of `base` with `corrections` set.
fn error(mut base: Value, corrections: Value) -> String {
    base["corrections"] = corrections;
    parse(&base.to_string(), "bad.json").unwrap_err().to_string()
}

#[test]
fn each_bad_value_is_named() {
    let cases: &[(Value, &str)] = &[
        (
            json!({"linear_drag": {"xy": -0.1, "z": 0.5}}),
            "bad.json: corrections.linear_drag.xy: must be finite and ≥ 0, found -0.1",
        ),
        (
            json!({"quadratic_drag": {"z": -1}}),
            "bad.json: corrections.quadratic_drag.z: must be finite and ≥ 0, found -1",
        ),
        (
            json!({"thrust_gain": -1.0}),
            "bad.json: corrections.thrust_gain: must be finite and > −1 (κ = m_assumed/m_true − 1), found -1",
        ),
        (
            json!({"ground_effect": {"gain": 1.0, "rotor_radius": 0.0}}),
            "bad.json: corrections.ground_effect.rotor_radius: must be finite and > 0 (m), found 0",
        ),
        (
            json!({"ground_effect": {"gain": -2.0, "rotor_radius": 0.2}}),
            "bad.json: corrections.ground_effect.gain: must be finite and ≥ 0, found -2",
        ),
        (
            json!({"actuator_lag": {"u_roll": 0.0}}),
            "bad.json: corrections.actuator_lag.u_roll: must be finite and > 0 (a time constant in s), found 0",
        ),
        (
            json!({"actuator_lag": {"u_pitch": -0.05}}),
            "bad.json: corrections.actuator_lag.u_pitch: must be finite and > 0 (a time constant in s), found -0.05",
        ),
        (
            json!({"latency": {"u_vz": -0.1}}),
            "bad.json: corrections.latency.u_vz: must be finite and ≥ 0 (a delay in s), found -0.1",
        ),
        (
            json!({"latency": {"u_thrust": 0.1}}),
            "bad.json: corrections.latency.u_thrust: 'u_thrust' is not an input (inputs: u_vz, u_roll, u_pitch, u_yaw_rate)",
        ),
        (
            json!({"actuator_lag": {"vx": 0.1}}),
            "bad.json: corrections.actuator_lag.vx: 'vx' is not an input (inputs: u_vz, u_roll, u_pitch, u_yaw_rate)",
        ),
        (
            json!({"acceleration_lag": {"roll": 0.1}}),
            "bad.json: corrections.acceleration_lag.roll: 'roll' is not a velocity or rate state (one of: vx, vy, vz, roll_rate, pitch_rate, yaw_rate)",
        ),
        (
            json!({"acceleration_lag": {"pitch_rate": 0.0}}),
            "bad.json: corrections.acceleration_lag.pitch_rate: must be finite and > 0 (a time constant in s), found 0",
        ),
    ];
    for base in [sindy(), pd()] {
        for (corrections, expected) in cases {
            assert_eq!(&error(base.clone(), corrections.clone()), expected);
        }
    }
}

#[test]
fn schema_errors_carry_the_path_under_corrections() {
    let cases: &[(Value, &str)] = &[
        (
            json!({"linear_drag": {"x": 0.1}}),
            "bad.json: corrections.linear_drag.x: unknown field `x`, expected `xy` or `z`",
        ),
        (
            json!({"wind": [1, 0, 0]}),
            "bad.json: corrections.wind: unknown field `wind`, expected one of `source`, `linear_drag`, `quadratic_drag`, `force_bias`, `thrust_gain`, `thrust_decay`, `ground_effect`, `actuator_lag`, `acceleration_lag`, `latency`, `input_gain`, `loop_mismatch`",
        ),
        (
            json!({"force_bias": [0.1, 0.2]}),
            "bad.json: corrections.force_bias: invalid length 2, expected an array of length 3",
        ),
        (
            json!({"thrust_gain": "high"}),
            "bad.json: corrections.thrust_gain: invalid type: string \"high\", expected f64",
        ),
        (
            json!({"thrust_decay": {}}),
            "bad.json: corrections.thrust_decay: missing field `per_second`",
        ),
        (
            json!({"latency": {"u_vz": "fast"}}),
            "bad.json: corrections.latency.u_vz: invalid type: string \"fast\", expected f64",
        ),
        (json!([1, 2]), "bad.json: corrections: expected an object, found [1,2]"),
    ];
    for (corrections, expected) in cases {
        assert_eq!(&error(sindy(), corrections.clone()), expected);
    }
    // A top-level typo lists `corrections` among the fields.
    let mut bad = sindy();
    bad["corections"] = json!({});
    let e = parse(&bad.to_string(), "bad.json").unwrap_err();
    assert_eq!(e.kind, ModelErrorKind::UnknownField);
    assert!(
        e.to_string().ends_with("`coefficients`, `corrections`, `envelope`"),
        "{e}"
    );
}

#[test]
fn non_finite_numbers_are_rejected() {
    // JSON cannot hold NaN: too large numbers are the non-finite values a file can contain.
    let mut base = sindy();
    base["corrections"] = json!({"force_bias": [0.0, 0.0, 0.0]});
    let text = base.to_string().replace("[0.0,0.0,0.0]", "[0.0,1e999,0.0]");
    let e = parse(&text, "bad.json").unwrap_err();
    assert_eq!(e.kind, ModelErrorKind::NonFinite, "{e}");
    // Built in code (e.g. by a diagnosis tool), the block is validated the same way.
    let c = uavgen::model::Corrections {
        force_bias: Some([0.0, f64::INFINITY, 0.0]),
        ..Default::default()
    };
    let states: Vec<String> = uavgen::model::DEFAULT_STATES.iter().map(|s| s.to_string()).collect();
    let inputs: Vec<String> = uavgen::model::DEFAULT_INPUTS.iter().map(|s| s.to_string()).collect();
    let e = c.validate("code", &states, &inputs).unwrap_err().to_string();
    assert_eq!(e, "code: corrections.force_bias[1]: must be finite, found inf");
    let c = uavgen::model::Corrections {
        thrust_decay: Some(uavgen::model::ThrustDecay { per_second: f64::NAN }),
        ..Default::default()
    };
    let e = c.validate("code", &states, &inputs).unwrap_err().to_string();
    assert_eq!(
        e,
        "code: corrections.thrust_decay.per_second: must be finite, found NaN"
    );
}

#[test]
fn corrections_need_the_standard_states() {
    let mut renamed = sindy();
    renamed["states"] = json!(["x", "y", "z", "roll", "pitch", "yaw", "u", "v", "w", "p", "q", "r"]);
    renamed["kinematic"] = json!([["z", "w"]]);
    renamed["coefficients"] = json!([{"state": "w", "term": "u_vz", "coefficient": 2.0}]);
    let e = error(renamed, json!({"thrust_gain": 0.1}));
    assert_eq!(
        e,
        "bad.json: corrections: corrections need the 12 standard states in the standard order \
         (x y z roll pitch yaw vx vy vz roll_rate pitch_rate yaw_rate), because the velocity and height rows \
         are found by these names; this model's states are: x y z roll pitch yaw u v w p q r"
    );
    let mut small = sindy();
    small["states"] = json!(["z", "vz"]);
    small["kinematic"] = json!([["z", "vz"]]);
    assert!(error(small, json!({})).starts_with("bad.json: corrections: corrections need the 12 standard states"));
}

#[test]
fn an_extra_state_may_not_take_an_input_name() {
    let mut base = sindy();
    base["inputs"] = json!(["u_vz", "flight_time"]);
    let e = error(base.clone(), json!({"thrust_decay": {"per_second": 0.001}}));
    assert_eq!(
        e,
        "bad.json: corrections.thrust_decay: the extra state 'flight_time' would have the name of an input"
    );
    base["inputs"] = json!(["u_vz", "u_vz_lagged"]);
    let e = error(base, json!({"actuator_lag": {"u_vz": 0.1}}));
    assert_eq!(
        e,
        "bad.json: corrections.actuator_lag.u_vz: the extra state 'u_vz_lagged' would have the name of an input"
    );
}

#[test]
fn an_empty_block_changes_nothing() {
    let mut base = sindy();
    base["corrections"] = json!({});
    let m = parse(&base.to_string(), "ok.json").unwrap();
    assert_eq!(m.nx(), 12);
    assert!(m.corrections.is_some());
}
