//! Parametric FaSTrack navigating seeded worlds over the real server on the shipped `dubins4d` model: on 20
//! worlds it must reach every goal with no collision and the tracking error never above the bound in force
//! (checked at every sub-step); the baselines run through the same worlds with the same sensor, dynamics and
//! control period, the reachability-based ones as safely.

use fastrack_e2e::{binary, run_binary, TestServer};
use fastrack_sim::bench::{summarise, table, time_ratio};
use fastrack_sim::episode::{Outcome, PlaneRun, RunSettings, Simulator};
use fastrack_sim::methods::{Method, MppiSettings};
use fastrack_sim::world::{PlaneWorld, WorldFamily, WorldSpec};
use std::path::Path;
use std::process::Command;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

/// Worlds of the CI run (the recorded benchmark runs 200).
const WORLDS: u64 = 20;

async fn shipped() -> (TestServer, Arc<Simulator>) {
    let (server, client) = TestServer::start_serving(&Path::new(env!("CARGO_MANIFEST_DIR")).join("../models")).await;
    let simulator = Simulator::connect(&client, RunSettings::default()).await.unwrap();
    (server, Arc::new(simulator))
}

fn worlds(count: u64, steb: f64) -> Vec<PlaneWorld> {
    (1..=count).map(|seed| WorldSpec { seed, inflation: steb, ..WorldSpec::default() }.generate().unwrap()).collect()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn parametric_fastrack_reaches_every_goal_safely_on_twenty_worlds() {
    let (_server, simulator) = shipped().await;
    let mut runs = Vec::new();
    for (i, world) in worlds(WORLDS, simulator.steb_radius()).into_iter().enumerate() {
        let done = simulator.spawn_run(world, Method::Parametric, i as u64 + 1).await.unwrap().unwrap();
        assert_eq!(done.outcome, Outcome::Reached, "world {}: {:?} after {:.1} s", i + 1, done.outcome, done.time);
        assert!(done.min_clearance > 0.0, "world {}", i + 1);
        assert!(
            done.worst_excess.is_some_and(|e| e <= 1e-9),
            "world {}: error over the bound by {:?}",
            i + 1,
            done.worst_excess
        );
        assert!(done.samples.iter().all(|s| s.bound.is_some() && s.error.is_some()), "every period checked");
        assert_eq!(done.out_of_domain, 0, "world {}: controls read outside the trained domain", i + 1);
        assert_eq!(done.uncertified_steps, 0, "world {}: steps past the certificate's horizon", i + 1);
        assert_eq!(done.visits.len(), done.samples.len(), "world {}: a visit recorded per period", i + 1);
        // The time at each beta adds up the periods the samples recorded at it.
        for &(beta, seconds) in &done.beta_seconds {
            let periods = done.samples.iter().filter(|s| s.beta == Some(beta)).count();
            assert!((seconds - periods as f64 * done.control_period).abs() < 1e-6, "world {}: beta {beta}", i + 1);
        }
        assert!(done.planning_times.len() == done.replans && done.replans > 0, "world {}: a time per replan", i + 1);
        let (beta_l, beta_u) = (simulator.speeds()[0].beta, simulator.speeds().last().unwrap().beta);
        let mean = done.mean_beta().expect("PF has a beta");
        assert!(mean >= beta_l && mean <= beta_u, "world {}: mean beta {mean}", i + 1);
        let above = done.share_above(beta_l);
        assert!((0.0..=1.0).contains(&above) && done.share_above(beta_u) == 0.0, "world {}: {above}", i + 1);
        runs.push(done);
    }
    let all: Vec<&PlaneRun> = runs.iter().collect();
    let summary = summarise("PF", &all);
    println!("{}", table(std::slice::from_ref(&summary)).to_markdown());
    assert_eq!((summary.reached, summary.collided, summary.bound_exceeded), (WORLDS as usize, 0, 0));
    let shares: f64 = summary.beta_shares.iter().map(|(_, share)| share).sum();
    assert!((shares - 1.0).abs() < 1e-9, "the shares of time add up to {shares}");
    let (beta_l, beta_u) = (simulator.speeds()[0].beta, simulator.speeds().last().unwrap().beta);
    assert!(summary.mean_beta().is_some_and(|b| b > beta_l && b < beta_u), "{:?}", summary.mean_beta());
    assert!(summary.planning_ms.is_some_and(|(mean, p99)| mean > 0.0 && p99 >= mean), "{:?}", summary.planning_ms);
    // The common branch costs one round trip per control step.
    let steps: usize = runs.iter().map(|r| r.samples.len()).sum();
    assert!(
        summary.round_trips * WORLDS as f64 <= 1.05 * steps as f64,
        "{} calls for {steps} steps",
        summary.round_trips
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_baselines_run_the_same_worlds_and_the_bounded_ones_stay_safe() {
    let (_server, simulator) = shipped().await;
    let worlds = worlds(3, simulator.steb_radius());
    let mut by_method: Vec<(Method, Vec<PlaneRun>)> = Vec::new();
    for method in Method::all() {
        let mut runs = Vec::new();
        for (i, world) in worlds.iter().enumerate() {
            runs.push(simulator.spawn_run(world.clone(), method.clone(), i as u64 + 1).await.unwrap().unwrap());
        }
        by_method.push((method, runs));
    }
    for (method, runs) in &by_method {
        for (i, r) in runs.iter().enumerate() {
            if !matches!(method, Method::Mppi(_)) {
                assert!(!r.outcome.is_unsafe(), "{} on world {}: {:?}", method.label(), i + 1, r.outcome);
            }
            // A method either drives, or gives up at once because no path keeps its bound (F(beta_u)'s
            // 2.7 m bound closes many gaps, the goal's among them).
            let gave_up_planning =
                matches!(&r.outcome, Outcome::Failed(why) if why.contains("not free") || why.contains("no path"));
            assert!(
                !r.samples.is_empty() || gave_up_planning,
                "{} on world {}: {:?}",
                method.label(),
                i + 1,
                r.outcome
            );
        }
    }
    let runs_of = |label: &str| {
        by_method.iter().find(|(m, _)| m.label() == label).map(|(_, r)| r.iter().collect::<Vec<_>>()).unwrap()
    };
    // On worlds both reach, PF is faster than FaSTrack at beta_l (the paper: 0.60).
    let (ratio, n) = time_ratio(&runs_of("PF"), &runs_of("F(beta_l)")).expect("PF and F(beta_l) both reach a goal");
    assert!(ratio < 1.0, "PF / F(beta_l) time to goal {ratio} over {n} worlds");
    // Under the planner rule PF is faster than Meta-FaSTrack, however it picks its levels.
    for mf in ["MF", "MF-quick"] {
        let (ratio, n) = time_ratio(&runs_of("PF-planner"), &runs_of(mf)).expect("both reach a goal");
        assert!(ratio < 1.0, "PF-planner / {mf} time to goal {ratio} over {n} worlds");
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_server_that_goes_away_mid_run_ends_the_run_with_a_reason() {
    let (mut server, simulator) = shipped().await;
    let world = worlds(1, simulator.steb_radius()).remove(0);
    let handle = simulator.spawn_run(world, Method::Parametric, 1);
    tokio::time::sleep(std::time::Duration::from_millis(300)).await;
    server.terminate();
    let done = handle.await.unwrap().unwrap();
    match &done.outcome {
        Outcome::Failed(why) => assert!(why.contains("navailable") || why.contains("closed"), "{why}"),
        Outcome::Reached => panic!("the run finished in 300 ms: the test needs a longer world"),
        other => panic!("expected a failure naming the server, got {other:?}"),
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 1)]
async fn a_run_never_holds_up_the_runtime_it_was_started_from() {
    // MPPI makes no server call: run as a task, it would hold the runtime's only worker for the whole run,
    // and with it every other task (the connection's among them). Run by spawn_run, a ticker task on that
    // worker keeps its 10 ms pace.
    let (_server, simulator) = shipped().await;
    let world = worlds(1, simulator.steb_radius()).remove(0);
    let finished = Arc::new(AtomicBool::new(false));
    let ticker = {
        let finished = Arc::clone(&finished);
        tokio::spawn(async move {
            let mut ticker = tokio::time::interval(Duration::from_millis(10));
            let (mut last, mut longest_gap) = (Instant::now(), Duration::ZERO);
            while !finished.load(Ordering::SeqCst) {
                ticker.tick().await;
                longest_gap = longest_gap.max(last.elapsed());
                last = Instant::now();
            }
            longest_gap
        })
    };
    let started = Instant::now();
    // 1024 samples, four times the default: a run long enough to tell a held worker from a busy one.
    let mppi = Method::Mppi(MppiSettings { samples: 1024, ..MppiSettings::default() });
    let done = simulator.spawn_run(world, mppi, 1).await.unwrap().unwrap();
    let wall = started.elapsed();
    finished.store(true, Ordering::SeqCst);
    let longest_gap = ticker.await.unwrap();
    assert_eq!(done.method, "MPPI");
    assert!(wall.as_secs_f64() > 1.0, "the run took {wall:?}: too short to tell");
    assert!(longest_gap.as_secs_f64() < 0.5, "the ticker waited {longest_gap:?} during a run of {wall:?}");
}

/// `sim world --feasible-for` generates a world for a larger sTEB than the model's (so that models of
/// different bounds run on the same worlds) and refuses one below the model's.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn worlds_generated_for_a_larger_steb_keep_it_clear() {
    let (server, simulator) = shipped().await;
    let steb = simulator.steb_radius();
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("world.toml");
    let world_args = |feasible_for: f64| {
        let mut args = vec!["--server".to_string(), server.endpoint.clone(), "sim".into(), "world".into()];
        args.extend(["--seed".into(), "4".into(), "--feasible-for".into(), feasible_for.to_string()]);
        args
    };
    let mut larger = world_args(steb + 0.6);
    larger.extend(["--out".into(), out.to_str().unwrap().into()]);
    run_binary("fastrack", &larger.iter().map(String::as_str).collect::<Vec<_>>());
    PlaneWorld::load(&out).unwrap().check_feasible(steb + 0.6).unwrap();
    let refused = Command::new(binary("fastrack")).args(world_args(steb * 0.5)).output().unwrap();
    let said = String::from_utf8_lossy(&refused.stderr);
    assert!(!refused.status.success() && said.contains("--feasible-for must be"), "{said}");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn every_world_family_is_driven_safely_by_parametric_fastrack_on_both_paths_and_rules_and_fastrack() {
    let (_server, simulator) = shipped().await;
    let steb = simulator.steb_radius();
    let mut lines = Vec::new();
    let mut unsafe_runs = Vec::new();
    for family in WorldFamily::ALL {
        for seed in 1..=2 {
            let world: PlaneWorld =
                WorldSpec { seed, family, inflation: steb, ..WorldSpec::default() }.generate().unwrap();
            for method in [
                Method::Parametric,
                Method::ParametricFastestPath,
                Method::ParametricPlannerRule,
                Method::FastrackSlowest,
                Method::FastrackFastest,
            ] {
                let run = simulator.spawn_run(world.clone(), method.clone(), seed).await.unwrap().unwrap();
                let line = format!(
                    "{} on {family} world {seed}: {} after {:.1} s, min clearance {:.3} m, {} steps the bound reached an obstacle",
                    method.label(),
                    run.outcome.label(),
                    run.time,
                    run.min_clearance,
                    run.exposed_steps
                );
                // Every planner keeps farther than the bound in force from every obstacle (FaSTrack's by its
                // inflation, PF's on every branch by the loop's clearance rule), so no bound reaches one.
                if run.outcome.is_unsafe()
                    || run.exposed_steps > 0
                    || (method.is_parametric() && run.outcome != Outcome::Reached)
                {
                    unsafe_runs.push(line.clone());
                }
                lines.push(line);
            }
        }
    }
    println!("{}", lines.join("\n"));
    // No collision and no error over the bound in force, on any family, no bound in force ever reaching an
    // obstacle, and PF reaching every goal on both raw paths and under both rules.
    assert!(unsafe_runs.is_empty(), "{}", unsafe_runs.join("\n"));
}
