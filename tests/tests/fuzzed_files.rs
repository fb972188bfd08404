//! World files and training configs nobody meant to write: a generated world (in the plane and in space) and
//! the shipped training config, each with one node replaced or removed, or the text cut short or a bit
//! flipped. Reading either never panics; a refusal names the file; a world that is accepted can be checked
//! for feasibility (the planner's search over it ends). `FASTRACK_FUZZ_CASES` sets the cases (default 300
//! each; half that for worlds in space).

use fastrack_e2e::fuzz::{cases, damage, json_text, toml_text, Tally};
use fastrack_online::geometry::{PlaneObstacle, SpaceObstacle};
use fastrack_sim::world::{World, WorldObstacle, WorldSpec};
use fastrack_trainer::config::TrainConfig;
use proptest::prelude::*;
use proptest::test_runner::{Config, TestRunner};
use std::cell::RefCell;
use std::path::{Path, PathBuf};

fn repository() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).parent().expect("the workspace root").to_path_buf()
}

#[test]
fn damaged_world_files_are_refused_by_field_or_file_and_accepted_ones_can_be_planned() {
    damaged_worlds::<PlaneObstacle, 2>("worlds", cases(300));
}

#[test]
fn damaged_world_files_in_space_are_refused_by_field_or_file_and_accepted_ones_can_be_planned() {
    damaged_worlds::<SpaceObstacle, 3>("worlds in space", cases(300) / 2);
}

/// Damaged copies of world 3 of `D` axes: each is refused naming the file or field, or checked.
fn damaged_worlds<O: WorldObstacle<D>, const D: usize>(label: &'static str, cases: u32) {
    let world: World<O, D> = WorldSpec { seed: 3, ..WorldSpec::default() }.generate().unwrap();
    let tree = serde_json::to_value(&world).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let config = Config { cases, failure_persistence: None, ..Config::default() };
    let tally = RefCell::new(Tally::new(label, config.cases));
    TestRunner::new(config)
        .run(&(damage(), any::<bool>()), |(damage, as_json)| {
            let (path, bytes) = if as_json {
                (dir.path().join("world.json"), damage.apply(&tree, json_text))
            } else {
                (dir.path().join("world.toml"), damage.apply(&tree, toml_text))
            };
            std::fs::write(&path, bytes).unwrap();
            match World::<O, D>::load(&path) {
                Ok(world) => {
                    tally.borrow_mut().count(damage.kind(), true);
                    // Feasible or not, the check ends with an answer.
                    let _ = world.check_feasible(0.5);
                }
                Err(e) => {
                    tally.borrow_mut().count(damage.kind(), false);
                    let text = e.to_string();
                    prop_assert!(text.contains("world.") || text.contains("world field `"), "{text}");
                }
            }
            Ok(())
        })
        .unwrap();
    let tally = tally.into_inner();
    tally.assert_both("");
    tally.report();
}

fn train_config_tree(path: &Path) -> serde_json::Value {
    let table: toml::Table = std::fs::read_to_string(path).unwrap().parse().unwrap();
    serde_json::to_value(table).unwrap()
}

#[test]
fn damaged_training_configs_are_refused_naming_the_file_before_any_work() {
    let tree = train_config_tree(&repository().join("trainer/configs/dubins4d.toml"));
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("config.toml");
    let config = Config { cases: cases(300), failure_persistence: None, ..Config::default() };
    let tally = RefCell::new(Tally::new("configs", config.cases));
    TestRunner::new(config)
        .run(&damage(), |damage| {
            std::fs::write(&path, damage.apply(&tree, toml_text)).unwrap();
            match TrainConfig::load(&path) {
                Ok(config) => {
                    tally.borrow_mut().count(damage.kind(), true);
                    prop_assert!(config.system().is_ok(), "an accepted config names a known system");
                }
                Err(e) => {
                    tally.borrow_mut().count(damage.kind(), false);
                    let text = format!("{e:#}");
                    prop_assert!(text.contains("config.toml"), "{text}");
                }
            }
            Ok(())
        })
        .unwrap();
    let tally = tally.into_inner();
    tally.assert_both("");
    tally.report();
}
