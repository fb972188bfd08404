"""Generated gRPC stubs of ``fastrack.v1`` (``models_pb2``, ``safety_pb2`` and their ``_grpc`` services).

The modules are written at build time from ``proto/fastrack/v1/*.proto`` (see ``setup.py``).
"""
