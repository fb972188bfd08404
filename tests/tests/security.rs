//! Security of the real server: bearer tokens (UNAUTHENTICATED, PERMISSION_DENIED), TLS and mutual TLS with
//! certificates generated here by rcgen.

use fastrack_client::{model_ref, ClientOptions, ClientTls};
use fastrack_e2e::{write_test_bundle, TestServer};
use fastrack_valuefn::system::dubins4d;
use rcgen::{BasicConstraints, CertificateParams, DnType, IsCa, Issuer, KeyPair};
use std::path::Path;
use std::time::Duration;

const USER: &str = "user-token-0123456789";
const ADMIN: &str = "admin-token-0123456789";

fn repository() -> tempfile::TempDir {
    let repo = tempfile::tempdir().unwrap();
    write_test_bundle(repo.path(), &dubins4d::system(), "dubins-test", 1, 1);
    repo
}

fn options(token: Option<&str>, tls: Option<ClientTls>) -> ClientOptions {
    ClientOptions {
        connect_timeout: Duration::from_secs(2),
        request_timeout: Duration::from_secs(10),
        bearer_token: token.map(str::to_string),
        tls,
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn tokens_authenticate_users_and_authorise_admins() {
    let repo = repository();
    let tokens = repo.path().join("tokens");
    std::fs::write(&tokens, format!("# fleet\nuser:{USER}\nadmin:{ADMIN}\n")).unwrap();
    let args = ["--tokens-file", tokens.to_str().unwrap(), "--log-level", "debug"];
    let (server, _) = TestServer::start_observed(repo.path(), &args).await;
    let endpoint = server.endpoint.clone();
    let anonymous = server.client().await;
    let wrong = server.client_with(&endpoint, options(Some("not-a-valid-token"), None)).await;
    let user = server.client_with(&endpoint, options(Some(USER), None)).await;
    let admin = server.client_with(&endpoint, options(Some(ADMIN), None)).await;

    // Health stays open for probes.
    anonymous.wait_until_serving(Duration::from_secs(60)).await.unwrap();
    for (who, client) in [("no token", &anonymous), ("wrong token", &wrong)] {
        let e = client.query_planner_control(model_ref("dubins-test", 0), Some(2.0)).await.unwrap_err();
        assert_eq!(e.code(), Some(tonic::Code::Unauthenticated), "{who}: {e}");
        let e = client.list_models().await.unwrap_err();
        assert_eq!(e.code(), Some(tonic::Code::Unauthenticated), "{who}: {e}");
    }
    let e = anonymous.list_models().await.unwrap_err();
    assert!(e.to_string().contains("Bearer"), "the message says what is missing: {e}");

    // A user token answers safety queries but not admin calls.
    user.query_planner_control(model_ref("dubins-test", 0), Some(2.0)).await.unwrap();
    let mut stream = user.track(model_ref("dubins-test", 0), 0.0).await.unwrap();
    assert!(stream.tick(fastrack_e2e::robot_tick(0, 0)).await.unwrap().error.is_none());
    let e = user.reload_model("dubins-test").await.unwrap_err();
    assert_eq!(e.code(), Some(tonic::Code::PermissionDenied), "{e}");
    assert!(e.to_string().contains("admin token"), "{e}");

    // An admin token does both.
    assert!(admin.reload_model("dubins-test").await.unwrap().iter().all(|o| o.loaded));
    admin.list_models().await.unwrap();
    let refused = server.metric(r#"fastrack_auth_failures_total{code="UNAUTHENTICATED"}"#).await;
    assert!(refused >= 4.0, "auth failures counted: {refused}");
    assert_eq!(server.metric(r#"fastrack_auth_failures_total{code="PERMISSION_DENIED"}"#).await, 1.0);
    // No token, right or wrong, reaches the log, even at debug level.
    let log = server.log_text();
    assert!(log.contains("call refused"), "the refusals are logged");
    for secret in [USER, ADMIN, "not-a-valid-token"] {
        assert!(!log.contains(secret), "the log holds a token");
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn tokens_from_files_one_per_file_as_a_mounted_secret_gives_them() {
    let repo = repository();
    let secret = tempfile::tempdir().unwrap();
    let (user, admin) = (secret.path().join("user-token"), secret.path().join("admin-token"));
    std::fs::write(&user, format!("{USER}\n")).unwrap();
    std::fs::write(&admin, ADMIN).unwrap();
    let (user, admin) = (user.to_str().unwrap(), admin.to_str().unwrap());
    let args = ["--user-token-file", user, "--admin-token-file", admin];
    let (server, anonymous) = TestServer::start_observed(repo.path(), &args).await;
    let e = anonymous.list_models().await.unwrap_err();
    assert_eq!(e.code(), Some(tonic::Code::Unauthenticated), "{e}");
    let cli = |token_file: &str, command: &str| {
        std::process::Command::new(fastrack_e2e::binary("fastrack"))
            .args(["--server", &server.endpoint, "--token-file", token_file, command, "dubins-test"])
            .output()
            .unwrap()
    };
    // The CLI reads its token from a file too: the user token answers, only the admin token reloads.
    let out = cli(user, "model");
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let out = cli(user, "reload-model");
    assert!(String::from_utf8_lossy(&out.stderr).contains("admin token"), "{}", String::from_utf8_lossy(&out.stderr));
    assert!(cli(admin, "reload-model").status.success());
    // A file that is not one token is refused before any call.
    let two = secret.path().join("two");
    std::fs::write(&two, "a b\n").unwrap();
    let out = cli(two.to_str().unwrap(), "model");
    assert!(
        String::from_utf8_lossy(&out.stderr).contains("exactly one token"),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}

/// A CA, a server certificate for `localhost` and a client certificate, as PEM files in `dir`.
struct Pki {
    ca: Vec<u8>,
    client_cert: Vec<u8>,
    client_key: Vec<u8>,
}

fn leaf(names: Vec<String>, issuer: &Issuer<'static, KeyPair>) -> (Vec<u8>, Vec<u8>) {
    let key = KeyPair::generate().unwrap();
    let mut params = CertificateParams::new(names).unwrap();
    params.distinguished_name.push(DnType::CommonName, "fastrack test");
    let cert = params.signed_by(&key, issuer).unwrap();
    (cert.pem().into_bytes(), key.serialize_pem().into_bytes())
}

fn make_pki(dir: &Path) -> Pki {
    let ca_key = KeyPair::generate().unwrap();
    let mut ca_params = CertificateParams::new(Vec::<String>::new()).unwrap();
    ca_params.is_ca = IsCa::Ca(BasicConstraints::Unconstrained);
    ca_params.distinguished_name.push(DnType::CommonName, "fastrack test CA");
    let ca = ca_params.self_signed(&ca_key).unwrap().pem().into_bytes();
    let issuer = Issuer::new(ca_params, ca_key);
    let (server_cert, server_key) = leaf(vec!["localhost".into()], &issuer);
    let (client_cert, client_key) = leaf(vec!["robot-7".into()], &issuer);
    std::fs::write(dir.join("ca.pem"), &ca).unwrap();
    std::fs::write(dir.join("server.pem"), server_cert).unwrap();
    std::fs::write(dir.join("server.key"), server_key).unwrap();
    Pki { ca, client_cert, client_key }
}

fn tls_args(dir: &Path, mutual: bool) -> Vec<String> {
    let mut args: Vec<String> = vec![
        "--tls-cert".into(),
        dir.join("server.pem").display().to_string(),
        "--tls-key".into(),
        dir.join("server.key").display().to_string(),
    ];
    if mutual {
        args.extend(["--tls-client-ca".into(), dir.join("ca.pem").display().to_string()]);
    }
    args
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn tls_and_mutual_tls_connections() {
    let repo = repository();
    let pki_dir = tempfile::tempdir().unwrap();
    let pki = make_pki(pki_dir.path());
    let server_only = ClientTls { ca_pem: pki.ca.clone(), identity: None, domain: Some("localhost".into()) };
    let with_identity =
        ClientTls { identity: Some((pki.client_cert.clone(), pki.client_key.clone())), ..server_only.clone() };

    // TLS: a client trusting the CA is served; a plaintext client is not.
    let args = tls_args(pki_dir.path(), false);
    let server = TestServer::start(repo.path(), &args.iter().map(String::as_str).collect::<Vec<_>>());
    let https = server.endpoint.replace("http://127.0.0.1", "https://localhost");
    let client = server.client_with(&https, options(None, Some(server_only.clone()))).await;
    client.wait_until_serving(Duration::from_secs(60)).await.unwrap();
    client.query_planner_control(model_ref("dubins-test", 0), Some(2.0)).await.unwrap();
    let plaintext = fastrack_client::FastrackClient::connect(&server.endpoint, options(None, None)).await;
    let plaintext_failed = match plaintext {
        Err(_) => true,
        Ok(c) => c.list_models().await.is_err(),
    };
    assert!(plaintext_failed, "a plaintext client must not be served by a TLS server");
    drop(server);

    // Mutual TLS: only a client with a certificate from the CA is served.
    let args = tls_args(pki_dir.path(), true);
    let server = TestServer::start(repo.path(), &args.iter().map(String::as_str).collect::<Vec<_>>());
    let https = server.endpoint.replace("http://127.0.0.1", "https://localhost");
    let robot = server.client_with(&https, options(None, Some(with_identity))).await;
    robot.wait_until_serving(Duration::from_secs(60)).await.unwrap();
    robot.query_planner_control(model_ref("dubins-test", 0), Some(2.0)).await.unwrap();
    let stranger = fastrack_client::FastrackClient::connect(&https, options(None, Some(server_only))).await;
    let stranger_failed = match stranger {
        Err(_) => true,
        Ok(c) => c.list_models().await.is_err(),
    };
    assert!(stranger_failed, "a client without a certificate must be refused under mutual TLS");
    let log = server.log_text();
    assert!(log.contains("tls=\"mutual\"") || log.contains("tls=mutual"));
    // No certificate or key content reaches the log.
    let pem_body = |pem: &[u8]| String::from_utf8_lossy(pem).lines().nth(1).unwrap_or_default().to_string();
    for secret in [pem_body(&pki.client_key), pem_body(&pki.client_cert), "PRIVATE KEY".to_string()] {
        assert!(!secret.is_empty() && !log.contains(&secret), "the log holds certificate or key content");
    }
}
