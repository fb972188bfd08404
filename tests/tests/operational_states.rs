//! The states the online loop puts robots in, recorded by the simulator against the real server
//! (`fastrack sim bench --visits`), are the operational distribution that verification checks beside the
//! uniform one (`fastrack-grid verify --operational-states`).

use fastrack_client::{model_ref, pb};
use fastrack_e2e::{run_binary, TestServer};
use serde_json::Value;
use std::path::Path;
use std::process::Command;

/// The visits file's lines after its header, sorted (runs at once finish in any order).
fn sorted_lines(path: &Path) -> (String, Vec<String>) {
    let text = std::fs::read_to_string(path).unwrap();
    let mut lines = text.lines().map(str::to_string);
    let header = lines.next().expect("a header");
    let mut rest: Vec<String> = lines.collect();
    rest.sort();
    (header, rest)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_loops_visits_are_recorded_and_verified_as_the_operational_distribution() {
    let models = Path::new(env!("CARGO_MANIFEST_DIR")).join("../models");
    let (server, client) = TestServer::start_serving(&models).await;
    let out = tempfile::tempdir().unwrap();
    let at = |name: &str| out.path().join(name).to_str().unwrap().to_string();
    let endpoint = server.endpoint.clone();
    let sim = move |extra: Vec<String>| {
        let mut args: Vec<String> = ["--server", &endpoint, "sim", "bench", "--worlds", "2", "--methods", "pf,f-low"]
            .map(String::from)
            .to_vec();
        args.extend(extra);
        run_binary("fastrack", &args.iter().map(String::as_str).collect::<Vec<_>>())
    };
    let (whole, parts) = (at("visits.csv"), at("parts"));
    let shard_visits = at("shard.csv");
    let said = tokio::task::spawn_blocking(move || {
        let mut said = sim(vec!["--visits".into(), whole]);
        for shard in ["0/2", "1/2"] {
            let extra = ["--shard", shard, "--part-dir", &parts, "--visits", &shard_visits];
            said += &sim(extra.map(String::from).to_vec());
        }
        said
    })
    .await
    .unwrap();
    let merged = at("merged.csv");
    run_binary("fastrack", &["sim", "merge", "--part-dir", &at("parts"), "--visits", &merged]);

    // One line per control period of PF (F(beta_l) has no online loop), the same whether sharded or not.
    let (header, lines) = sorted_lines(Path::new(&at("visits.csv")));
    assert_eq!(header, "branch,beta,x_r,y_r,theta,v", "{said}");
    assert!(lines.len() > 200, "{} visits", lines.len());
    assert_eq!(sorted_lines(Path::new(&merged)), (header.clone(), lines.clone()));

    // Each visit is a row's beta and a relative state; a keep or a reset put the state in that row's
    // certified set, as the server answers membership.
    let info = client.get_model(model_ref("dubins4d", 5)).await.unwrap();
    let betas: Vec<f64> = info.teb_table.iter().map(|row| row.beta).collect();
    let (mut branches, mut checked) = (std::collections::BTreeMap::<String, usize>::new(), Vec::new());
    for line in &lines {
        let fields: Vec<&str> = line.split(',').collect();
        let numbers: Vec<f64> = fields[1..].iter().map(|f| f.parse().unwrap()).collect();
        assert!(betas.iter().any(|&b| b == numbers[0]), "beta {} is no table row's", numbers[0]);
        *branches.entry(fields[0].to_string()).or_default() += 1;
        if matches!(fields[0], "keep" | "reset") {
            checked.push(numbers);
        }
    }
    assert!(
        branches.keys().all(|b| ["advance", "steady", "keep", "reset", "hold"].contains(&b.as_str())),
        "{branches:?}"
    );
    assert!(branches.get("advance").is_some_and(|&n| n > 100), "{branches:?}");
    if !checked.is_empty() {
        let states = checked.iter().flat_map(|n| n[1..].to_vec()).collect();
        let params = checked.iter().map(|n| n[0]).collect();
        let reply =
            client.evaluate_value(model_ref("dubins4d", 5), states, params, pb::OutOfDomainPolicy::Flag).await.unwrap();
        assert!(reply.in_teb.iter().all(|&inside| inside), "a keep or reset outside the certified set");
    }

    // Verification draws its operational check from them: as many draws as the uniform check has samples.
    let bundle = models.join("dubins4d/5");
    let results = at("results");
    let verify = |states: &str| {
        Command::new(fastrack_e2e::binary("fastrack-grid"))
            .args(["verify", "--bundle", bundle.to_str().unwrap(), "--betas", "1.25", "--eps", "0.2"])
            .args(["--delta", "0.2", "--horizon", "0.5", "--step", "0.05", "--results-dir", &results])
            .args(["--record", "operational", "--out", &at("verified"), "--operational-states", states])
            .output()
            .unwrap()
    };
    let done = verify(&at("visits.csv"));
    assert!(done.status.success(), "{}", String::from_utf8_lossy(&done.stderr));
    let record: Value =
        serde_json::from_slice(&std::fs::read(out.path().join("results/operational.json")).unwrap()).unwrap();
    let checks = &record["figures"]["rows"][0]["verification"]["checks"];
    let names: Vec<&str> = checks.as_array().unwrap().iter().map(|c| c["distribution"].as_str().unwrap()).collect();
    assert_eq!(names, ["uniform", "zero-error-slice", "operational", "falsification"], "{checks}");
    assert_eq!(checks[2]["samples"], 8, "N = ceil(ln 0.2 / ln 0.8) draws: {checks}");
    assert_eq!(record["config"]["operational_recorded"]["states"], lines.len());
    // Beside it, the states recorded while this row was in force and how many of them left its set.
    let in_force = &record["figures"]["rows"][0]["rounds"][0]["in_force"];
    let with_row = lines.iter().filter(|l| l.split(',').nth(1) == Some("1.25")).count();
    assert_eq!(in_force["recorded"], with_row, "{in_force}");
    assert!(in_force["outside"].as_u64().is_some_and(|n| n <= with_row as u64), "{in_force}");

    // A file of another model's states, or a broken one, is refused naming what is wrong.
    std::fs::write(at("quad.csv"), "branch,beta,x_r,y_r,z_r\nadvance,1,0,0,0\n").unwrap();
    std::fs::write(at("broken.csv"), format!("{header}\nadvance,1.25,0,0,0\n")).unwrap();
    for (file, expected) in
        [("quad.csv", "the header is `branch,beta,x_r,y_r,z_r`"), ("broken.csv", "line 2: 5 fields")]
    {
        let refused = verify(&at(file));
        let said = String::from_utf8_lossy(&refused.stderr);
        assert!(!refused.status.success() && said.contains(expected), "{file}: {said}");
    }
}
