//! Every invalid-model case gets an error that names the file, the field or
//! entry, and the problem.

use uavgen::model::{parse, ModelError, ModelErrorKind as K};

const PD: &str = r#"{
  "format": "uavgen-model/1",
  "kind": "pd",
  "name": "t",
  "mass": 2.4,
  "gravity": 9.81,
  "xi": [1, 1, 1, 1, 1, 1, 1, 1, 1, 1, 0, 0, 23.544, 0.05, 0.05, 0.09]
}"#;

const SINDY: &str = r#"{
  "format": "uavgen-model/1",
  "kind": "sindy",
  "name": "t",
  "library": ["1", "vx", "sin(pitch)", "vx*u_vz"],
  "kinematic": [["x", "vx"]],
  "coefficients": [
    {"state": "vx", "term": "sin(pitch)", "coefficient": 9.81},
    {"state": "vx", "term": "vx", "coefficient": -0.4}
  ]
}"#;

fn err(text: &str) -> ModelError {
    match parse(text, "bad.json") {
        Ok(_) => panic!("accepted an invalid model:\n{text}"),
        Err(e) => e,
    }
}

fn assert_err(text: &str, kind: K, location: &str, needles: &[&str]) {
    let e = err(text);
    let msg = e.to_string();
    assert_eq!(e.kind, kind, "{msg}");
    assert_eq!(e.location, location, "{msg}");
    assert!(msg.starts_with("bad.json: "), "message must name the file: {msg}");
    for n in needles {
        assert!(msg.contains(n), "message must mention '{n}': {msg}");
    }
}

#[test]
fn valid_examples_parse() {
    let pd = parse(PD, "pd.json").unwrap();
    assert_eq!(pd.nx(), 12);
    let s = parse(SINDY, "s.json").unwrap();
    assert_eq!(s.nu(), 4);
    // Named ξ are the same as ordered ones.
    let named = PD.replace(
        "[1, 1, 1, 1, 1, 1, 1, 1, 1, 1, 0, 0, 23.544, 0.05, 0.05, 0.09]",
        r#"{"xi1": 1, "xi2": 1, "xi3": 1, "xi4": 1, "xi5": 1, "xi6": 1, "xi7": 1, "xi8": 1, "xi9": 1,
            "xi10": 1, "xi11": 0, "xi12": 0, "xi13": 23.544, "xi14": 0.05, "xi15": 0.05, "xi16": 0.09}"#,
    );
    let named = parse(&named, "pd.json").unwrap();
    match (named.dynamics, pd.dynamics) {
        (uavgen::model::Dynamics::Pd(a), uavgen::model::Dynamics::Pd(b)) => assert_eq!(a, b),
        _ => panic!("not PD"),
    }
}

#[test]
fn unknown_variable() {
    assert_err(
        &SINDY.replace(r#""vx*u_vz""#, r#""vw*u_vz""#),
        K::UnknownVariable,
        "library[3]",
        &["'vw'", "vw*u_vz"],
    );
    assert_err(
        &SINDY.replace(r#"{"state": "vx", "term": "vx""#, r#"{"state": "vq", "term": "vx""#),
        K::UnknownVariable,
        "coefficients[1].state",
        &["'vq'"],
    );
    assert_err(
        &SINDY.replace(r#"["x", "vx"]"#, r#"["x", "speed"]"#),
        K::UnknownVariable,
        "kinematic[0][1]",
        &["'speed'"],
    );
    assert_err(
        &SINDY.replace(r#""term": "vx""#, r#""term": "vy""#),
        K::UnknownVariable,
        "coefficients[1].term",
        &["'vy' is not in the library"],
    );
}

#[test]
fn bad_term_syntax() {
    assert_err(
        &SINDY.replace(r#""vx*u_vz""#, r#""vx**u_vz""#),
        K::BadTerm,
        "library[3]",
        &["bad term syntax", "vx**u_vz"],
    );
    assert_err(
        &SINDY.replace(r#""sin(pitch)", "vx"#, r#""sin(pitch", "vx"#),
        K::BadTerm,
        "library[2]",
        &["sin(pitch"],
    );
    assert_err(
        &SINDY.replace(r#""vx*u_vz""#, r#""vx^0""#),
        K::BadTerm,
        "library[3]",
        &["power 0"],
    );
}

#[test]
fn non_finite_coefficient() {
    // Python's json module writes NaN/Infinity, which JSON does not have.
    assert_err(
        &SINDY.replace("9.81", "NaN"),
        K::NonFinite,
        "line 8, column 58",
        &["non-finite"],
    );
    assert_err(
        &SINDY.replace("-0.4", "-Infinity"),
        K::NonFinite,
        "line 9, column 51",
        &["non-finite"],
    );
    assert_err(
        &SINDY.replace("9.81", "1e999"),
        K::NonFinite,
        "line 8, column 62",
        &["non-finite"],
    );
    assert_err(
        &PD.replace("23.544", "NaN"),
        K::NonFinite,
        "line 7, column 46",
        &["non-finite"],
    );
}

#[test]
fn duplicate_entry() {
    let dup = SINDY.replace(
        r#""vx", "coefficient": -0.4}"#,
        r#""vx", "coefficient": -0.4}, {"state": "vx", "term": "vx", "coefficient": 1.0}"#,
    );
    assert_err(
        &dup,
        K::Duplicate,
        "coefficients[2]",
        &["duplicate entry", "'vx'", "coefficients[1]"],
    );
    // The same term written another way is the same library entry.
    assert_err(
        &SINDY
            .replace(r#""vx*u_vz""#, r#""u_vz vx""#)
            .replace(r#""1", "vx""#, r#""vx*u_vz", "vx""#),
        K::Duplicate,
        "library[3]",
        &["duplicates library[0]"],
    );
    assert_err(
        &SINDY.replace(r#"[["x", "vx"]]"#, r#"[["x", "vx"], ["x", "vy"]]"#),
        K::Duplicate,
        "kinematic[1]",
        &["'x'", "twice"],
    );
    assert_err(
        &SINDY.replace(r#"[["x", "vx"]]"#, r#"[["vx", "vy"]]"#),
        K::Duplicate,
        "coefficients[0]",
        &["'vx' is kinematic"],
    );
}

#[test]
fn missing_field() {
    assert_err(
        &PD.replace(r#""format": "uavgen-model/1","#, ""),
        K::MissingField,
        "format",
        &["`format`"],
    );
    assert_err(
        &PD.replace(r#""kind": "pd","#, ""),
        K::MissingField,
        "kind",
        &["`kind`"],
    );
    assert_err(
        &PD.replace(r#""mass": 2.4,"#, ""),
        K::MissingField,
        "",
        &["missing field `mass`"],
    );
    assert_err(
        &SINDY.replace(r#""library": ["1", "vx", "sin(pitch)", "vx*u_vz"],"#, ""),
        K::MissingField,
        "",
        &["`library`"],
    );
    assert_err(
        &SINDY.replace(r#", "coefficient": -0.4"#, ""),
        K::MissingField,
        "coefficients[1]",
        &["`coefficient`"],
    );
    let named = PD.replace(
        "[1, 1, 1, 1, 1, 1, 1, 1, 1, 1, 0, 0, 23.544, 0.05, 0.05, 0.09]",
        r#"{"xi1": 1}"#,
    );
    assert_err(&named, K::MissingField, "xi.xi2", &["`xi2`"]);
}

#[test]
fn wrong_count() {
    assert_err(
        &PD.replace("[1, 1, 1, ", "[1, 1, "),
        K::WrongCount,
        "xi",
        &["16", "found 15"],
    );
    let states = PD.replace(
        r#""name": "t","#,
        r#""name": "t", "states": ["a","b","c","d","e","f","g","h","i","j","k"],"#,
    );
    assert_err(&states, K::WrongCount, "states", &["12 states", "found 11"]);
    let inputs = PD.replace(r#""name": "t","#, r#""name": "t", "inputs": ["a","b","c"],"#);
    assert_err(&inputs, K::WrongCount, "inputs", &["4 inputs", "found 3"]);
}

#[test]
fn unknown_format_version_and_kind() {
    assert_err(
        &PD.replace("uavgen-model/1", "uavgen-model/2"),
        K::UnknownFormat,
        "format",
        &["uavgen-model/2", "uavgen-model/1"],
    );
    assert_err(
        &PD.replace(r#""kind": "pd""#, r#""kind": "koopman""#),
        K::UnknownKind,
        "kind",
        &["koopman"],
    );
}

#[test]
fn unknown_fields_and_bad_values() {
    assert_err(
        &PD.replace(r#""mass": 2.4,"#, r#""mass": 2.4, "masss": 1,"#),
        K::UnknownField,
        "masss",
        &["unknown field `masss`"],
    );
    assert_err(
        &PD.replace(r#""mass": 2.4"#, r#""mass": -1"#),
        K::BadValue,
        "mass",
        &["positive"],
    );
    assert_err(
        &PD.replace("0.05, 0.05, 0.09", "0.05, 0.0, 0.09"),
        K::BadValue,
        "xi[14]",
        &["ξ15 = Iy", "positive"],
    );
    assert_err(
        &PD.replace("1, 0, 0, 23.544", "1, -2.4, 0, 23.544"),
        K::BadValue,
        "xi[10]",
        &["ξ11", "singular"],
    );
    assert_err(
        &PD.replace("1, 0, 0, 23.544", "1, 2.5, 0, 23.544"),
        K::BadValue,
        "xi[10]",
        &["ξ11", "singular"],
    );
    assert_err(
        &PD.replace("1, 0, 0, 23.544", "1, 0, -0.07, 23.544"),
        K::BadValue,
        "xi[11]",
        &["ξ12", "singular"],
    );
    let named = PD.replace("[1, 1, 1, 1, 1, 1, 1, 1, 1, 1, 0, 0, 23.544, 0.05, 0.05, 0.09]", r#"{"xi1": 1, "xi2": 1, "xi3": 1, "xi4": 1, "xi5": 1, "xi6": 1, "xi7": 1, "xi8": 1, "xi9": 1, "xi10": 1, "xi11": 0, "xi12": 0, "xi13": 23.544, "xi14": -0.05, "xi15": 0.05, "xi16": 0.09}"#);
    assert_err(&named, K::BadValue, "xi.xi14", &["ξ14 = Ix"]);
    assert_err(
        &PD.replace(r#""mass": 2.4"#, r#""mass": "heavy""#),
        K::BadValue,
        "mass",
        &["invalid type"],
    );
    let named = PD.replace(
        "[1, 1, 1, 1, 1, 1, 1, 1, 1, 1, 0, 0, 23.544, 0.05, 0.05, 0.09]",
        r#"{"xi0": 1}"#,
    );
    assert_err(
        &named,
        K::UnknownField,
        "xi.xi0",
        &["unknown parameter 'xi0'", "xi1..xi16"],
    );
    let dup_state = SINDY.replace(r#""name": "t","#, r#""name": "t", "states": ["vx", "vx"],"#);
    assert_err(&dup_state, K::Duplicate, "states[1]", &["'vx'", "states[0]"]);
    assert_err(
        &PD.replace("{\n", "[\n"),
        K::Json,
        "line 2, column 11",
        &["invalid JSON"],
    );
}
