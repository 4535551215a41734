"""The two messages of ``grpc.health.v1.Health/Check``, without the grpcio-health-checking package.

Debian ships no Python module for the standard health protocol and the build generates Python
stubs for animspace.v1 only, so the messages are declared here from their descriptor (the
protocol is frozen: ``HealthCheckRequest { string service = 1; }`` and ``HealthCheckResponse {
ServingStatus status = 1; }``) in a private descriptor pool, which cannot clash with a
``grpc_health`` module the application may also import. The result is ordinary protobuf
messages, serialised by the protobuf runtime rather than by hand.
"""
from __future__ import annotations

from typing import Any, Type

from google.protobuf import descriptor_pb2, descriptor_pool, message_factory

__all__ = ["HealthCheckRequest", "HealthCheckResponse", "CHECK_METHOD", "serving_status_name"]

CHECK_METHOD = "/grpc.health.v1.Health/Check"

_PACKAGE = "grpc.health.v1"


def _declare() -> descriptor_pool.DescriptorPool:
    file = descriptor_pb2.FileDescriptorProto(name="animspace/client/grpc_health_v1.proto", package=_PACKAGE,
                                              syntax="proto3")
    request = file.message_type.add(name="HealthCheckRequest")
    request.field.add(name="service", number=1, type=descriptor_pb2.FieldDescriptorProto.TYPE_STRING,
                      label=descriptor_pb2.FieldDescriptorProto.LABEL_OPTIONAL, json_name="service")
    response = file.message_type.add(name="HealthCheckResponse")
    status = response.enum_type.add(name="ServingStatus")
    for number, name in enumerate(["UNKNOWN", "SERVING", "NOT_SERVING", "SERVICE_UNKNOWN"]):
        status.value.add(name=name, number=number)
    response.field.add(name="status", number=1, type=descriptor_pb2.FieldDescriptorProto.TYPE_ENUM,
                       type_name=f".{_PACKAGE}.HealthCheckResponse.ServingStatus",
                       label=descriptor_pb2.FieldDescriptorProto.LABEL_OPTIONAL, json_name="status")
    pool = descriptor_pool.DescriptorPool()
    pool.AddSerializedFile(file.SerializeToString())
    return pool


def _message_class(pool: descriptor_pool.DescriptorPool, name: str) -> Type[Any]:
    descriptor = pool.FindMessageTypeByName(f"{_PACKAGE}.{name}")
    get_class = getattr(message_factory, "GetMessageClass", None)  # protobuf ≥ 4.22
    if get_class is not None:
        return get_class(descriptor)
    return message_factory.MessageFactory(pool).GetPrototype(descriptor)


_POOL = _declare()
HealthCheckRequest = _message_class(_POOL, "HealthCheckRequest")
HealthCheckResponse = _message_class(_POOL, "HealthCheckResponse")
_SERVING_STATUS = _POOL.FindEnumTypeByName(f"{_PACKAGE}.HealthCheckResponse.ServingStatus")


def serving_status_name(value: int) -> str:
    """"SERVING", "NOT_SERVING", "UNKNOWN", "SERVICE_UNKNOWN" (or the number, for a newer status)."""
    found = _SERVING_STATUS.values_by_number.get(value)
    return found.name if found is not None else str(value)
