//! Every shipped trained model's promise in closed loop through the real server (`fastrack sim promise`'s
//! check): at its slowest, middle and fastest rows, a tracker integrated by the simulator takes its control
//! from a `Track` stream kept at the row, from the centre of the row's certified set and from the set's edge
//! along random rays, against the worst case of the served gradient and a random bang-bang planner. From
//! every start the server places in the set the error stays within the row's bound.

use fastrack_client::model_ref;
use fastrack_e2e::TestServer;
use fastrack_sim::promise::{PromiseCheck, PromiseOptions};
use std::path::Path;

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn from_starts_across_each_certified_set_the_error_stays_within_the_bound() {
    let repo = Path::new(env!("CARGO_MANIFEST_DIR")).join("../models");
    let (_server, client) = TestServer::start_serving(&repo).await;
    let trained: Vec<_> = client.list_models().await.unwrap().into_iter().filter(|m| !m.untrained).collect();
    assert!(!trained.is_empty(), "a trained model is shipped");
    let options = PromiseOptions { starts: 6, random_planners: 1, ..PromiseOptions::default() };
    for info in trained {
        let check = PromiseCheck::new(client.clone(), model_ref(&info.name, info.version)).await.unwrap();
        let rows = check.rows();
        // Settings it cannot run with are refused, naming what is wrong.
        let off_table = check.row(rows[0].beta + 1e-3, &options).await.expect_err("refused");
        assert!(off_table.to_string().contains("no row at beta"), "{off_table}");
        let backwards = PromiseOptions { horizon: Some(-1.0), ..options.clone() };
        let refused = check.row(rows[0].beta, &backwards).await.expect_err("refused");
        assert!(refused.to_string().contains("horizon must be a positive number"), "{refused}");
        for beta in [rows[0].beta, rows[rows.len() / 2].beta, rows[rows.len() - 1].beta] {
            let row = check.row(beta, &options).await.unwrap();
            eprintln!(
                "{}/{} beta {beta}: {} starts in the set, largest error {:.4} (worst case {:.4}) against the bound \
                 {:.4}, {} ticks out of the domain",
                info.name,
                info.version,
                row.certified_starts,
                row.largest_error(),
                row.worst_case_error,
                row.bound,
                row.out_of_domain_ticks
            );
            assert!(row.certified_starts >= 1, "{} beta {beta}: the set's centre is served as inside", info.name);
            assert!(row.ticks > 0);
            assert!(
                row.kept(),
                "{} beta {beta}: from {:?} the error reached {:.4}, past the bound {:.4}",
                info.name,
                row.worst_start,
                row.largest_error(),
                row.bound
            );
        }
    }
}
