use super::*;

fn compile(formula: &str) -> Result<Compiled, SpecError> {
    RequirementSpec {
        name: "r".into(),
        formula: formula.into(),
        weight: 1.0,
    }
    .compile("requirement[0]", 0.1)
}

fn signals_with(speed: &[f64], peer: &[f64]) -> Vec<Vec<f64>> {
    let mut s = vec![Vec::new(); 8];
    s[0] = speed.to_vec();
    s[2] = peer.to_vec();
    s
}

#[test]
fn robustness_is_the_formulas_value_at_sample_0() {
    let s = signals_with(&[0.1, 0.5, 0.2, 0.0], &[3.0, 1.0, 0.3, 2.0]);
    let rho = |f: &str| compile(f).unwrap().verdict(&s, 4, 0.1).robustness.unwrap();
    assert_eq!(rho("always (speed < 0.6)"), 0.09999999999999998);
    assert_eq!(rho("always (peer_distance > 0.4)"), 0.3 - 0.4);
    assert_eq!(rho("eventually[0:0.1] speed > 0.4"), 0.09999999999999998);
    // Past the trace's end `always` holds vacuously.
    assert_eq!(rho("always[1:2] speed > 10"), f64::INFINITY);
    assert_eq!(rho("speed > 0.2 until peer_distance < 0.5"), -0.1);
    assert_eq!(rho("prev speed > 0"), f64::INFINITY);
}

#[test]
fn a_violation_says_when_it_began_and_what_decided_it() {
    let s = signals_with(&[0.1, 0.5, 0.6, 0.7, 0.2, 0.3], &[1.0; 6]);
    let v = compile("always (speed < 0.55)")
        .unwrap()
        .verdict(&s, 6, 0.1);
    assert!(v.violated);
    assert_eq!(v.first_violation_s, Some(0.2));
    assert_eq!(v.interval_s, Some([0.2, 0.3]));
    let v = compile("eventually[0:0.3] speed > 0.8")
        .unwrap()
        .verdict(&s, 6, 0.1);
    assert_eq!(
        (v.first_violation_s, v.interval_s),
        (Some(0.3), Some([0.0, 0.3]))
    );
}

#[test]
fn bad_formulas_are_one_line_errors_naming_the_column() {
    let err = |f: &str| compile(f).unwrap_err().to_string();
    assert_eq!(
        err("always (speed < )"),
        "requirement[0].formula: column 17: expected a signal, a number, '(' or an operator, found ')'"
    );
    assert!(err("always (sped < 1)")
        .contains("unknown signal 'sped'; the signals are speed, turn_rate,"));
    assert!(err("always[0:0.15] speed < 1").contains("not a whole number of steps"));
    assert!(err("speed / 2 * 3 > 1").contains("write ( ) around '/ *'"));
    assert!(err("speed - 2 + 3 > 1").contains("write ( ) around '- +'"));
    let deep = format!("{}speed > 0{}", "(".repeat(500), ")".repeat(500));
    assert!(err(&deep).contains("nests deeper than"));
    let bad = RequirementSpec {
        name: "collision".into(),
        formula: "speed < 1".into(),
        weight: 1.0,
    };
    assert!(bad
        .compile("r", 0.1)
        .unwrap_err()
        .to_string()
        .contains("one of sitgen's own classes"));
}

#[test]
fn a_long_flat_formula_is_read_without_deep_recursion() {
    let long = vec!["speed < 1"; 5000].join(" and ");
    let c = compile(&long).unwrap();
    let s = signals_with(&[0.5; 10], &[1.0; 10]);
    assert_eq!(c.verdict(&s, 10, 0.1).robustness, Some(0.5));
}

#[test]
fn unless_reads_as_rtamt_rewrites_it() {
    let s = signals_with(&[0.1, 0.5, 0.2, 0.0], &[3.0, 1.0, 0.3, 2.0]);
    let a = compile("(speed < 0.4) unless[0:0.2] (peer_distance < 0.5)").unwrap();
    let b = compile(
        "always[0:0.2] (speed < 0.4) or ((speed < 0.4) until[0:0.2] (peer_distance < 0.5))",
    )
    .unwrap();
    assert_eq!(
        a.verdict(&s, 4, 0.1).robustness,
        b.verdict(&s, 4, 0.1).robustness
    );
}

#[test]
fn each_signals_index_is_its_place_among_the_names() {
    use crate::monitor::signals::*;
    let named = [
        ("speed", SPEED),
        ("turn_rate", TURN_RATE),
        ("peer_distance", PEER_DISTANCE),
        ("peer_clearance", PEER_CLEARANCE),
        ("obstacle_clearance", OBSTACLE_CLEARANCE),
        ("goal_distance", GOAL_DISTANCE),
        ("closing_speed", CLOSING_SPEED),
        ("peer_seen", PEER_SEEN),
    ];
    for (name, i) in named {
        assert_eq!(index(name), Some(i), "{name}");
    }
}
