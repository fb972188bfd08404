"""Each status the server answers with arrives as its exception, carrying the server's message and code."""

from __future__ import annotations

import asyncio
from collections.abc import Iterator

import grpc
import numpy as np
import pytest

import fastrack
from conftest import ADMIN_TOKEN, MODEL, USER_TOKEN, VERSION, Server
from fastrack.errors import from_rpc_error
from fastrack.v1 import models_pb2, safety_pb2, safety_pb2_grpc

STATE = [[0.2, -0.1, 0.3, 1.0]]


def test_nan_in_states_is_refused_by_the_server(client: fastrack.Client) -> None:
    with pytest.raises(fastrack.InvalidArgument) as refused:
        client.evaluate(MODEL, [[0.2, -0.1, float("nan"), 1.0]], 1.0)
    assert refused.value.message == "states[2] (item 0, theta) is NaN; must be a finite number"
    assert refused.value.code == grpc.StatusCode.INVALID_ARGUMENT


def test_wrong_shapes_are_refused_before_sending(client: fastrack.Client) -> None:
    with pytest.raises(fastrack.InvalidArgument) as states:
        client.evaluate(MODEL, [[0.1, 0.2, 0.3]], 1.0)
    assert states.value.message.startswith("states has shape [1, 3]; model dubins4d/5 needs [N, n_state] = [N, 4]")
    with pytest.raises(fastrack.InvalidArgument, match=r"states has shape \[4\]"):
        client.tracking_control(MODEL, [0.1, 0.2, 0.3, 1.0], 1.0)
    with pytest.raises(fastrack.InvalidArgument, match=r"params has shape \[2, 2\]; .* needs \[N, n_params\] = \[1, 1\]"):
        client.tracking_control(MODEL, STATE, [[1.0, 1.0], [1.0, 1.0]])
    with pytest.raises(fastrack.InvalidArgument, match="states must be an array of numbers"):
        client.evaluate(MODEL, [["a", "b", "c", "d"]], 1.0)
    with pytest.raises(fastrack.InvalidArgument, match="out_of_domain = 'never'"):
        client.evaluate(MODEL, STATE, 1.0, out_of_domain="never")  # type: ignore[arg-type]


def test_a_raw_request_of_the_wrong_length_reaches_the_server(client: fastrack.Client) -> None:
    stub = safety_pb2_grpc.SafetyServiceStub(client.channel)
    request = safety_pb2.EvaluateValueRequest(
        model=models_pb2.ModelRef(name=MODEL), states=[0.1, 0.2, 0.3, 1.0, 0.5], params=[1.0]
    )
    with pytest.raises(grpc.RpcError) as raw:
        stub.EvaluateValue(request, timeout=5)
    error = from_rpc_error(raw.value)
    assert isinstance(error, fastrack.InvalidArgument)
    assert error.message == (
        "states has 5 values; must be a positive multiple of n_state = 4 (x_r, y_r, theta, v), row-major [N x 4]"
    )


def test_parameters_and_beta_out_of_range(client: fastrack.Client) -> None:
    with pytest.raises(fastrack.InvalidArgument) as beta:
        client.tracking_error_bound(MODEL, beta=2.0)
    assert beta.value.message == "beta = 2 is outside the model's parameter range [0.5, 1.25] m/s"
    with pytest.raises(fastrack.InvalidArgument, match=r"params\[0\] \(item 0, beta\) = 2 is outside the trained range"):
        client.tracking_control(MODEL, STATE, 2.0)
    with pytest.raises(fastrack.InvalidArgument, match="boundary_points = 5000; must be at most 4096"):
        client.tracking_error_bound(MODEL, beta=1.0, boundary_points=5000)
    with pytest.raises(fastrack.InvalidArgument, match="d_obs = -1; must be a finite distance >= 0"):
        client.query_planner_control(MODEL, d_obs=-1.0)


def test_unknown_model_and_version(client: fastrack.Client) -> None:
    with pytest.raises(fastrack.NotFound) as model:
        client.query_planner_control("dubins4x")
    assert model.value.message == 'model "dubins4x" is not loaded; loaded models: dubins4d, untrained-dubins4d'
    assert model.value.code == grpc.StatusCode.NOT_FOUND
    with pytest.raises(fastrack.NotFound, match='model "dubins4d" has no loaded version 7'):
        client.evaluate(MODEL, STATE, 1.0, version=7)


def test_out_of_domain_with_the_reject_policy(client: fastrack.Client) -> None:
    states = np.array([[0.2, -0.1, 0.3, 1.0], [3.5, 0.0, 0.0, 1.0]])
    with pytest.raises(fastrack.OutOfRange) as outside:
        client.evaluate(MODEL, states, 1.0, out_of_domain="reject")
    assert outside.value.message.startswith("states[4] (item 1, x_r) = 3.5 is outside the trained domain [-3, 3] m")
    with pytest.raises(fastrack.OutOfRange):  # one item: rejected by default
        client.tracking_control(MODEL, states[1:], 1.0)


def test_per_call_deadline(client: fastrack.Client) -> None:
    with pytest.raises(fastrack.DeadlineExceeded):
        client.evaluate(MODEL, np.zeros((4096, 4)) + [0, 0, 0, 1], 1.0, timeout=1e-4)
    assert client.evaluate(MODEL, STATE, 1.0, timeout=10.0).values.shape == (1,)


def test_unreachable_server_is_unavailable() -> None:
    from conftest import free_port

    with fastrack.Client(f"127.0.0.1:{free_port()}", retry=fastrack.Retry(attempts=2, initial_backoff=0.01)) as c:
        with pytest.raises(fastrack.Unavailable):
            c.list_models()


def test_unusable_settings_are_named() -> None:
    with pytest.raises(fastrack.ConfigError, match="needs TLS settings"):
        fastrack.Client("https://127.0.0.1:1")
    with pytest.raises(fastrack.ConfigError, match="must start with https://"):
        fastrack.Client("http://127.0.0.1:1", tls=fastrack.Tls(ca="/no/such/ca.pem"))
    with pytest.raises(fastrack.ConfigError, match="cannot read /no/such/ca.pem"):
        fastrack.Client("127.0.0.1:1", tls=fastrack.Tls(ca="/no/such/ca.pem"))
    with pytest.raises(fastrack.ConfigError, match="no PEM BEGIN CERTIFICATE"):
        fastrack.Client("127.0.0.1:1", tls=fastrack.Tls(ca=b"not a certificate"))
    with pytest.raises(fastrack.ConfigError, match="printable ASCII"):
        fastrack.Client("127.0.0.1:1", token="a\nb")
    with pytest.raises(fastrack.ConfigError, match="expected host:port"):
        fastrack.Client("localhost")
    with pytest.raises(fastrack.ConfigError, match="attempts >= 1"):
        fastrack.Retry(attempts=0)
    assert "secret-token" not in repr(fastrack.Client("127.0.0.1:1", token="secret-token").settings)


@pytest.fixture(scope="module")
def authed(auth_server: Server) -> Iterator[dict[str, fastrack.Client]]:
    clients = {
        role: fastrack.Client(auth_server.address, token=token)
        for role, token in [("none", None), ("wrong", "not-a-known-token"), ("user", USER_TOKEN), ("admin", ADMIN_TOKEN)]
    }
    yield clients
    for c in clients.values():
        c.close()


def test_no_or_unknown_token_is_unauthenticated(authed: dict[str, fastrack.Client]) -> None:
    with pytest.raises(fastrack.Unauthenticated) as missing:
        authed["none"].list_models()
    assert missing.value.message == "missing `authorization: Bearer <token>` metadata"
    with pytest.raises(fastrack.Unauthenticated, match="the bearer token is not recognised"):
        authed["wrong"].query_planner_control(MODEL)
    assert authed["none"].health() == "SERVING"  # health stays open for probes


def test_user_token_on_an_admin_call_is_permission_denied(authed: dict[str, fastrack.Client]) -> None:
    user = authed["user"]
    assert user.query_planner_control(MODEL, 2.5).beta_query == pytest.approx(0.75)
    with user.track(MODEL) as robot:  # streams carry the token too
        assert robot.tick([0.0, 0.0, 0.0, 1.0], [0.0, 0.0]).seq == 0
    with pytest.raises(fastrack.PermissionDenied) as denied:
        user.reload_model(MODEL)
    assert denied.value.message == "this service needs an admin token; the token given is a user token"
    admin = authed["admin"]
    outcomes = admin.reload_model(MODEL)
    assert [(o.name, o.version, o.loaded) for o in outcomes] == [(MODEL, VERSION, True)]
    assert admin.load_model(MODEL, VERSION) == [VERSION]
    with pytest.raises(fastrack.NotFound, match="the repository has no folder dubins4d/9"):
        admin.load_model(MODEL, 9)


async def test_async_client_sends_the_token(auth_server: Server) -> None:
    async with fastrack.AsyncClient(auth_server.address) as anonymous:
        with pytest.raises(fastrack.Unauthenticated):
            await anonymous.list_models()
    async with fastrack.AsyncClient(auth_server.address, token=USER_TOKEN) as user:
        assert len(await user.list_models()) == 2
        async with user.track(MODEL) as robot:
            assert (await robot.tick([0.0, 0.0, 0.0, 1.0], [0.0, 0.0])).seq == 0
        with pytest.raises(fastrack.PermissionDenied):
            await user.unload_model(MODEL, VERSION)


async def test_a_full_queue_is_resource_exhausted() -> None:
    """One compute thread and a queue of one state: concurrent batches beyond it are shed at once."""
    server = Server("--compute-threads", "1", "--queue-capacity", "1").start().wait_serving()
    try:
        async with fastrack.AsyncClient(server.address, retry=fastrack.Retry(attempts=1)) as client:
            states = np.zeros((2048, 4)) + [0.1, 0.1, 0.0, 1.0]
            await client.dims(MODEL)
            outcomes: list[object] = []
            for _ in range(5):  # a round sheds unless the single thread kept up with every call
                outcomes = await asyncio.gather(
                    *(client.tracking_control(MODEL, states, 1.0) for _ in range(32)), return_exceptions=True
                )
                if any(isinstance(o, fastrack.ResourceExhausted) for o in outcomes):
                    break
        shed = [o for o in outcomes if isinstance(o, fastrack.ResourceExhausted)]
        assert shed, f"no call was shed: {outcomes!r}"
        assert "server overloaded" in shed[0].message and "retry with backoff" in shed[0].message
        assert all(isinstance(o, (fastrack.TrackingControl, fastrack.ResourceExhausted)) for o in outcomes)
    finally:
        server.close()
