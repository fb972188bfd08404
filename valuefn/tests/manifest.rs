//! Manifest validation and bundle checks: each failure names its field or file.

use fastrack_valuefn::bundle::{scan_repository, Bundle, BundleError, MAX_MANIFEST_BYTES};
use fastrack_valuefn::manifest::{
    AxisNetworkInfo, BoundSource, Manifest, NetworkInfo, Provenance, Reference, SystemInfo, TebRow, Verification,
    COMPOSITE_KIND, SCHEMA_VERSION,
};
use fastrack_valuefn::network::PeriodicEncoding;
use fastrack_valuefn::system::dubins4d;

fn manifest() -> Manifest {
    let system = dubins4d::system();
    let (state, planner_to_state, params, controls) = Manifest::describe_system(&system);
    Manifest {
        schema_version: SCHEMA_VERSION,
        name: "m".into(),
        version: 1,
        system: SystemInfo { id: "dubins4d".into(), description: "d".into() },
        state,
        planner_to_state,
        params,
        controls,
        horizon: 1.0,
        network: NetworkInfo {
            kind: "siren".into(),
            hidden: vec![8],
            omega_0: 30.0,
            exact_boundary: true,
            periodic_encoding: PeriodicEncoding::Circle,
            axes: Vec::new(),
        },
        teb_table: (0..16)
            .map(|k| TebRow {
                beta: 0.5 + 0.05 * k as f64,
                level: 0.3 + 0.01 * k as f64,
                measured_min: 0.3,
                extent: vec![0.1, 0.1],
                boundary_radii: vec![0.1; 8],
                nested_share: None,
                reference: None,
                verification: None,
            })
            .collect(),
        untrained: true,
        provenance: Provenance::untrained("test", serde_json::Value::Null),
        onnx_sha256: "0".repeat(64),
    }
}

fn field_error(m: Manifest) -> String {
    let err = m.validate().expect_err("must be rejected");
    format!("{}: {}", err.field, err.problem)
}

#[test]
fn valid_manifest_round_trips_through_json() {
    let m = manifest();
    m.validate().unwrap();
    assert_eq!(Manifest::from_json(&m.to_json()).unwrap(), m);
}

#[test]
fn each_invariant_names_its_field() {
    let mut m = manifest();
    m.schema_version = 2;
    assert!(field_error(m).starts_with("schema_version: must be 1, got 2"));
    let mut m = manifest();
    m.version = 0;
    assert!(field_error(m).starts_with("version:"));
    let mut m = manifest();
    m.state[0].max = f64::NAN;
    assert!(field_error(m).starts_with("state[0] (x_r): bounds must be finite"));
    let mut m = manifest();
    m.params[1].min = 2.0;
    assert!(field_error(m).starts_with("params[1] (beta_2): min must be < max"));
    let mut m = manifest();
    m.teb_table.truncate(5);
    assert!(field_error(m).contains("at least 16 rows, got 5"));
    let mut m = manifest();
    m.teb_table[7].level = 0.1;
    assert!(field_error(m).starts_with("teb_table[7]: bounds must not decrease"));
    let mut m = manifest();
    m.teb_table[3].verification = Some(Verification {
        verified_level: m.teb_table[3].level,
        eps: 0.1,
        delta: 0.1,
        samples: 10,
        violations: 0,
        horizon: 1.0,
        step: 0.01,
        sampled_level: Some(f64::NAN),
        correction: Some("bound".into()),
        rounds: 1,
        planners: Vec::new(),
        checks: Vec::new(),
    });
    assert!(field_error(m).starts_with("teb_table[3]: verification.sampled_level must be finite and > 0"));
    let mut m = manifest();
    m.teb_table[15].beta = 1.2;
    assert!(field_error(m).contains("must span the parameter range [0.5, 1.25]"));
    let mut m = manifest();
    m.planner_to_state.pop();
    assert!(field_error(m).starts_with("planner_to_state: must have one row per state coordinate (4), got 3"));
    let mut m = manifest();
    m.network.kind = COMPOSITE_KIND.into();
    assert!(field_error(m).starts_with("network.axes: a `siren-axes` network lists its axes, and only it does"));
    let mut m = manifest();
    m.network.axes.push(AxisNetworkInfo {
        subsystem: "x".into(),
        coords: vec![0, 4],
        param: 0,
        horizon: 1.0,
        hidden: vec![8],
        omega_0: 30.0,
        exact_boundary: true,
    });
    assert!(field_error(m.clone()).starts_with("network.axes: a `siren-axes`"), "axes on a plain siren");
    m.network.kind = COMPOSITE_KIND.into();
    assert!(field_error(m).starts_with("network.axes[0].coords: coordinate 4 is not below n_state = 4"));
    let mut m = manifest();
    m.onnx_sha256 = "ABC".into();
    assert!(field_error(m).starts_with("onnx_sha256: must be 64 lowercase hex digits"));
}

#[test]
fn schema_violations_are_reported() {
    let err = Manifest::from_json("{\"schema_version\": 1}").unwrap_err();
    assert_eq!(err.field, "(schema)");
    assert!(err.problem.contains("missing field"), "{}", err.problem);
}

#[test]
fn bundle_checksum_and_location_are_checked() {
    let root = tempfile::tempdir().unwrap();
    let dir = Bundle::write(root.path(), manifest(), b"graph bytes").unwrap();
    let loaded = Bundle::load(&dir).unwrap();
    assert_eq!(loaded.onnx, b"graph bytes");
    std::fs::write(dir.join("model.onnx"), b"graph bytez").unwrap();
    assert!(matches!(Bundle::load(&dir), Err(BundleError::Checksum { .. })));
    let moved = root.path().join("m").join("2");
    std::fs::create_dir_all(&moved).unwrap();
    std::fs::copy(dir.join("manifest.json"), moved.join("manifest.json")).unwrap();
    let err = Bundle::load(&moved).unwrap_err();
    assert!(err.to_string().contains("folder says m/2, manifest says m/1"), "{err}");
}

#[cfg(unix)]
#[test]
fn a_served_repository_is_read_only_inside_itself_and_only_as_bounded_regular_files() {
    use std::os::unix::fs::symlink;
    let root = tempfile::tempdir().unwrap();
    let outside = tempfile::tempdir().unwrap();
    let dir = Bundle::write(root.path(), manifest(), b"graph bytes").unwrap();
    Bundle::load_within(root.path(), &dir).unwrap();

    // A link that stays inside the repository is followed (mounted volumes are made of such links).
    let shared = root.path().join("shared.onnx");
    std::fs::rename(dir.join("model.onnx"), &shared).unwrap();
    symlink(&shared, dir.join("model.onnx")).unwrap();
    assert_eq!(Bundle::load_within(root.path(), &dir).unwrap().onnx, b"graph bytes");

    // A link leading out of it is refused, naming both ends; a tool reading a bundle anywhere follows it.
    let stolen = outside.path().join("model.onnx");
    std::fs::copy(&shared, &stolen).unwrap();
    std::fs::remove_file(dir.join("model.onnx")).unwrap();
    symlink(&stolen, dir.join("model.onnx")).unwrap();
    let err = Bundle::load_within(root.path(), &dir).unwrap_err();
    assert!(matches!(err, BundleError::OutsideRepository { .. }), "{err}");
    assert!(err.to_string().contains("outside the model repository") && err.to_string().contains("model.onnx"));
    Bundle::load(&dir).unwrap();

    // So is a version folder that is a link out of the repository, though the scan lists it.
    let mut elsewhere = manifest();
    elsewhere.version = 2;
    let foreign = Bundle::write(outside.path(), elsewhere, b"graph bytes").unwrap();
    symlink(&foreign, root.path().join("m").join("2")).unwrap();
    let (found, _) = scan_repository(root.path()).unwrap();
    let linked = found.iter().find(|v| v.version == 2).expect("a linked version folder is listed");
    let err = Bundle::load_within(root.path(), &linked.path).unwrap_err();
    assert!(matches!(err, BundleError::OutsideRepository { .. }), "{err}");

    // A device in place of the graph is not read (it would never end), nor a manifest past the size limit.
    std::fs::remove_file(dir.join("model.onnx")).unwrap();
    symlink("/dev/zero", dir.join("model.onnx")).unwrap();
    let err = Bundle::load(&dir).unwrap_err();
    assert!(matches!(err, BundleError::NotAFile { .. }), "{err}");
    std::fs::File::create(dir.join("manifest.json")).unwrap().set_len(MAX_MANIFEST_BYTES + 1).unwrap();
    let err = Bundle::load(&dir).unwrap_err();
    assert!(err.to_string().contains("more than the 16777216 a bundle's manifest may have"), "{err}");

    // A dangling link is skipped with its reason; the scan itself goes on.
    symlink(root.path().join("nowhere"), root.path().join("ghost")).unwrap();
    let (found, skipped) = scan_repository(root.path()).unwrap();
    assert_eq!(found.len(), 2);
    let (_, why) = skipped.iter().find(|(p, _)| p.ends_with("ghost")).expect("the dangling link is reported");
    assert!(why.contains("dangling"), "{why}");
}

/// A verification of `row` that sampled `{V <= sampled}` with `correction` and reached `verified`.
fn verified(row: &TebRow, sampled: f64, verified: f64, correction: &str) -> TebRow {
    TebRow {
        verification: Some(Verification {
            verified_level: verified,
            eps: 1e-3,
            delta: 1e-6,
            samples: 29_632,
            violations: 0,
            horizon: 10.0,
            step: 0.01,
            sampled_level: Some(sampled),
            correction: Some(correction.into()),
            rounds: 2,
            planners: Vec::new(),
            checks: Vec::new(),
        }),
        ..row.clone()
    }
}

#[test]
fn a_row_serves_the_set_it_certified_and_the_bound_from_inside_it() {
    let row = TebRow {
        beta: 0.5,
        level: 0.5876,
        measured_min: 0.5876,
        extent: vec![0.6, 0.6],
        boundary_radii: Vec::new(),
        nested_share: None,
        reference: None,
        verification: None,
    };
    // Unverified: the learned level for both.
    assert_eq!((row.set_level(), row.bound()), (0.5876, 0.5876));
    // The `bound` correction: the first round's set, the bound raised to the largest error (dubins4d/4, 0.5).
    let by_bound = verified(&row, 0.6515, 0.7300, "bound");
    assert_eq!((by_bound.set_level(), by_bound.bound()), (0.6515, 0.7300));
    // The error never reached the set's level: inside the set `|e| <= V <= 0.6515` already, so the bound
    // is the level.
    let below = verified(&row, 0.6515, 0.6400, "bound");
    assert_eq!((below.set_level(), below.bound()), (0.6515, 0.6515));
    // The `set` correction: one number for both.
    let by_set = verified(&row, 0.7300, 0.7300, "set");
    assert_eq!(by_set.set_level(), by_set.bound());
    // Never below the learned level.
    let low = verified(&row, 0.3, 0.3, "set");
    assert_eq!((low.set_level(), low.bound()), (0.3, 0.5876));
    assert_eq!([row.bound_source(), by_bound.bound_source()], [BoundSource::Learned, BoundSource::Verification]);
}

#[test]
fn a_ground_truth_reference_above_what_verification_reached_sets_the_bound_and_never_the_set() {
    let row = TebRow {
        beta: 1.0,
        level: 3.90,
        measured_min: 3.90,
        extent: vec![1.0; 3],
        boundary_radii: Vec::new(),
        nested_share: None,
        verification: None,
        reference: Some(Reference { bound: 4.05, source: "grid quad10d_x beta 1 (x, y); closed form (z)".into() }),
    };
    // Unverified: the reference lifts the bound, the set stays the learned level.
    assert_eq!((row.set_level(), row.bound(), row.bound_source()), (3.90, 4.05, BoundSource::Reference));
    // Verified below the reference: the reference still sets the bound; membership is the certified set.
    let below = verified(&row, 3.95, 4.00, "bound");
    assert_eq!((below.set_level(), below.verified_bound(), below.bound()), (3.95, 4.00, 4.05));
    assert_eq!(below.bound_source(), BoundSource::Reference);
    // Verified above it: verification sets the bound.
    let above = verified(&row, 3.95, 4.10, "bound");
    assert_eq!((above.bound(), above.bound_source()), (4.10, BoundSource::Verification));
    // It survives the manifest's JSON.
    let text = serde_json::to_string(&below).unwrap();
    assert_eq!(serde_json::from_str::<TebRow>(&text).unwrap(), below);
}
