"""The server's reflection answers ``grpc.reflection.v1alpha``, as Python's grpcio-reflection speaks it."""

from __future__ import annotations

from typing import cast

import grpc
from grpc_reflection.v1alpha import reflection_pb2, reflection_pb2_grpc

from conftest import Server


def test_reflection_lists_the_services(server: Server) -> None:
    with grpc.insecure_channel(server.address) as channel:
        stub = reflection_pb2_grpc.ServerReflectionStub(channel)
        info = cast(  # typed here: the stub package's annotation of this attribute is wrong
            "grpc.StreamStreamMultiCallable[reflection_pb2.ServerReflectionRequest, reflection_pb2.ServerReflectionResponse]",
            stub.ServerReflectionInfo,
        )
        request = reflection_pb2.ServerReflectionRequest(list_services="")
        responses = list(info(iter([request]), timeout=5))
    names = {s.name for s in responses[0].list_services_response.service}
    assert {"fastrack.v1.SafetyService", "fastrack.v1.ModelService", "fastrack.v1.ModelAdminService"} <= names
    assert "grpc.health.v1.Health" in names
