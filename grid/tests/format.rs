//! The `.ftgrid` format: a solution survives a save/load round trip bit for bit, damaged files are rejected
//! with a message, and the TEB analysis reads a loaded solution like the original.

use fastrack_grid::analysis::teb;
use fastrack_grid::format::{load, save, FormatError};
use fastrack_grid::grid::Grid;
use fastrack_grid::solver::{solve, SolverConfig};
use fastrack_valuefn::system::double_integrator::system;

fn small_solution() -> fastrack_grid::solver::Solution {
    let system = system();
    let grid = Grid::for_system(&system, &[41, 31]).unwrap();
    solve(&system, &[0.75], &grid, &SolverConfig { horizon_cap: 1.0, ..SolverConfig::default() }, false).unwrap()
}

#[test]
fn round_trip_is_exact() {
    let solution = small_solution();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("s.ftgrid");
    save(&solution, &path).unwrap();
    let loaded = load(&path).unwrap();
    assert_eq!(loaded, solution);
    let system = system();
    assert_eq!(teb(&loaded, &system, 0.02), teb(&solution, &system, 0.02));
    // Interpolation at a node returns the node's value.
    let mut r = [0.0; 2];
    solution.grid.point(123, &mut r);
    assert_eq!(loaded.grid.interpolate(&loaded.values, &r), solution.values[123]);
}

#[test]
fn damaged_files_are_rejected_with_a_reason() {
    let solution = small_solution();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("s.ftgrid");
    save(&solution, &path).unwrap();
    let bytes = std::fs::read(&path).unwrap();
    let cases: [(&str, Vec<u8>, &str); 3] = [
        ("magic", [b"NOTAGRID".as_slice(), &bytes[8..]].concat(), "magic"),
        ("truncated", bytes[..bytes.len() - 8].to_vec(), "bytes of values"),
        ("header length", [&bytes[..8], &u64::MAX.to_le_bytes()[..], &bytes[16..]].concat(), "runs past the end"),
    ];
    for (what, damaged, expected) in cases {
        let bad = dir.path().join(format!("{what}.ftgrid"));
        std::fs::write(&bad, damaged).unwrap();
        match load(&bad) {
            Err(FormatError::Invalid { problem, .. }) => assert!(problem.contains(expected), "{what}: {problem}"),
            other => panic!("{what}: expected an invalid-file error, got {other:?}"),
        }
    }
    assert!(matches!(load(&dir.path().join("missing.ftgrid")), Err(FormatError::Io { .. })));
}
