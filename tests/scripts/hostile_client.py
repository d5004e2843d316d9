#!/usr/bin/env python3
"""The hostile-client suite: stock grpcio against a running deog map server.

The client knows nothing of deog but the server's address: it learns the
API by server reflection (v1alpha, as grpcio-reflection asks), builds its
messages from the descriptors it is given, and then behaves badly: it
pipelines tiny update batches beside a watch on the same connection, holds
70 unread read streams while another client reads, publishes a poisoned
frame, sends bytes that are no protobuf, and opens silent sockets past the
connection limit. Each check prints `ok NAME ...` or `FAILED NAME: why`;
the exit status is the number of failed checks.

Usage: hostile_client.py HOST:PORT [--batches N]
The server must run with `--max-connections 8` (the silent-socket check
fills that many places and more).
"""

import argparse
import socket
import sys
import threading
import time

import grpc
from google.protobuf import descriptor_pool, message_factory
from grpc_health.v1 import health_pb2, health_pb2_grpc
from grpc_reflection.v1alpha import reflection_pb2, reflection_pb2_grpc
from grpc_reflection.v1alpha.proto_reflection_descriptor_database import (
    ProtoReflectionDescriptorDatabase,
)

MAP_SERVICE = "deog.v1.MapService"
# Every call is bounded: a check that hangs fails instead.
DEADLINE_S = 60


def own_channel(target):
    """A channel on a connection of its own (grpcio shares them otherwise)."""
    return grpc.insecure_channel(target, options=[("grpc.use_local_subchannel_pool", 1)])


class Api:
    """deog's messages and methods, as reflection describes them."""

    def __init__(self, channel):
        self.channel = channel
        self.pool = descriptor_pool.DescriptorPool(ProtoReflectionDescriptorDatabase(channel))
        self.service = self.pool.FindServiceByName(MAP_SERVICE)

    def message(self, name):
        return message_factory.GetMessageClass(self.pool.FindMessageTypeByName("deog.v1." + name))

    def method(self, name, channel=None):
        method = self.service.FindMethodByName(name)
        output = message_factory.GetMessageClass(method.output_type)
        kind = {
            (False, False): "unary_unary",
            (False, True): "unary_stream",
            (True, True): "stream_stream",
        }[(method.client_streaming, method.server_streaming)]
        return getattr(channel or self.channel, kind)(
            f"/{MAP_SERVICE}/{name}",
            request_serializer=lambda m: m.SerializeToString(),
            response_deserializer=output.FromString,
        )


RESULTS = []


def check(name):
    def wrap(body):
        def run(*args):
            started = time.monotonic()
            try:
                detail = body(*args) or ""
                RESULTS.append(True)
                print(f"ok {name} ({time.monotonic() - started:.1f} s) {detail}", flush=True)
            except Exception as error:  # a failed check, whatever raised
                RESULTS.append(False)
                print(f"FAILED {name}: {type(error).__name__}: {error}", flush=True)

        return run

    return wrap


def expect(condition, why):
    if not condition:
        raise AssertionError(why)


@check("reflection: services, files, an unknown symbol answered inside the stream")
def reflection(api, channel):
    services = set(ProtoReflectionDescriptorDatabase(channel).get_services())
    wanted = {
        MAP_SERVICE,
        "grpc.health.v1.Health",
        "grpc.reflection.v1.ServerReflection",
        "grpc.reflection.v1alpha.ServerReflection",
    }
    expect(services == wanted, f"listed {sorted(services)}")
    for name in wanted:
        api.pool.FindServiceByName(name)
    stub = reflection_pb2_grpc.ServerReflectionStub(channel)
    asked = [
        reflection_pb2.ServerReflectionRequest(file_containing_symbol="no.such.Thing"),
        reflection_pb2.ServerReflectionRequest(file_containing_symbol=MAP_SERVICE),
    ]
    answers = list(stub.ServerReflectionInfo(iter(asked), timeout=DEADLINE_S))
    expect(len(answers) == 2, f"{len(answers)} answers to 2 requests")
    expect(answers[0].HasField("error_response"), "no error answer for an unknown symbol")
    expect(answers[0].error_response.error_code == grpc.StatusCode.NOT_FOUND.value[0],
           f"code {answers[0].error_response.error_code}")
    expect(answers[1].HasField("file_descriptor_response"), "no file after the error")
    return f"{len(services)} services"


@check("health: the map service serving, an unknown one SERVICE_UNKNOWN on a watch kept open")
def health(channel):
    stub = health_pb2_grpc.HealthStub(channel)
    status = stub.Check(health_pb2.HealthCheckRequest(service=MAP_SERVICE), timeout=DEADLINE_S)
    expect(status.status == health_pb2.HealthCheckResponse.SERVING, f"{status}")
    watch = stub.Watch(health_pb2.HealthCheckRequest(service="no.such.Service"), timeout=DEADLINE_S)
    first = next(watch)
    expect(first.status == health_pb2.HealthCheckResponse.SERVICE_UNKNOWN, f"{first}")
    expect(watch.is_active(), "the watch ended after SERVICE_UNKNOWN")
    watch.cancel()


def create_map(api, name):
    create = api.method("CreateMap")
    request = api.message("CreateMapRequest")(name=name, resolution_m=0.05, tile_size=64)
    return create(request, timeout=DEADLINE_S)


@check("pipelined one-cell batches beside a watch on the same connection")
def pipelined(api, batches):
    create_map(api, "pipelined")
    Batch, Delta, Key = api.message("UpdateBatch"), api.message("TileDelta"), api.message("TileKey")
    Watch, Box = api.message("WatchTilesRequest"), api.message("CellBox")
    watch = api.method("WatchTiles")(
        Watch(map="pipelined", region=Box(min_x=0, min_y=0, max_x=63, max_y=63)),
        timeout=DEADLINE_S * 3)
    events = [0]

    def read_watch():
        try:
            for _ in watch:
                events[0] += 1
        except grpc.RpcError:
            pass

    reader = threading.Thread(target=read_watch, daemon=True)
    reader.start()
    sparse = api.pool.FindEnumTypeByName("deog.v1.CellEncoding").values_by_name[
        "CELL_ENCODING_SPARSE_I16_LE"].number

    def batches_to_send():
        for sequence in range(1, batches + 1):
            cell = (sequence % 4096).to_bytes(2, "little") + (1).to_bytes(2, "little", signed=True)
            yield Batch(map="pipelined", client_id="pipeliner", sequence=sequence,
                        tiles=[Delta(key=Key(x=0, y=0), encoding=sparse, cells=cell)])

    acks = 0
    last = 0
    for ack in api.method("ApplyUpdates")(batches_to_send(), timeout=DEADLINE_S * 3):
        acks += 1
        last = ack.sequence
    expect(acks == batches and last == batches, f"{acks} acknowledgements, the last {last}")
    time.sleep(0.5)
    # (Its code is asked only once it has ended: code() waits for the end.)
    if not watch.is_active():
        raise AssertionError(f"the watch on the same connection ended: {watch.code()}")
    expect(events[0] > 0, "the watch saw no change")
    watch.cancel()
    reader.join(5)
    return f"{acks} batches acknowledged, {events[0]} watch events"


@check("70 unread read streams on one connection; another client read within 1 s, every time")
def unread_streams(api, target):
    create_map(api, "big")
    Batch, Delta, Key = api.message("UpdateBatch"), api.message("TileDelta"), api.message("TileKey")
    dense = api.pool.FindEnumTypeByName("deog.v1.CellEncoding").values_by_name[
        "CELL_ENCODING_DENSE_I16_LE"].number
    cells = (5).to_bytes(2, "little", signed=True) * (64 * 64)

    def tiles():
        for sequence in range(1, 17):
            yield Batch(map="big", client_id="filler", sequence=sequence, tiles=[
                Delta(key=Key(x=sequence, y=y), encoding=dense, cells=cells) for y in range(20)])

    for _ in api.method("ApplyUpdates")(tiles(), timeout=DEADLINE_S):
        pass
    Query, Box, Keys = api.message("TileQuery"), api.message("CellBox"), api.message("TileKeys")
    whole = Query(map="big", region=Box(min_x=-100000, min_y=-100000, max_x=100000, max_y=100000))
    hog_channel = own_channel(target)
    hog = [api.method("GetTiles", hog_channel)(whole, timeout=DEADLINE_S) for _ in range(70)]
    time.sleep(1.0)
    reader_channel = own_channel(target)
    read_one = api.method("GetTiles", reader_channel)
    slowest = 0.0
    for _ in range(20):
        asked = time.monotonic()
        got = list(read_one(Query(map="big", keys=Keys(keys=[Key(x=3, y=0)])), timeout=DEADLINE_S))
        slowest = max(slowest, time.monotonic() - asked)
        expect(len(got) == 1, f"{len(got)} tiles for one key")
        time.sleep(0.1)
    expect(slowest < 1.0, f"the slowest read took {slowest:.2f} s")
    for call in hog:
        call.cancel()
    hog_channel.close()
    reader_channel.close()
    return f"slowest of 20 reads {slowest * 1000:.0f} ms"


@check("a poisoned frame refused at the door with INVALID_ARGUMENT naming the field")
def poisoned_frame(api):
    Frame, Pose, Request = api.message("SonarFrame"), api.message("Pose2"), api.message(
        "PublishFramesRequest")
    good = Frame(robot="poisoned", sequence=1, time_s=1.0, odometry=Pose(), ranges=[1.0] * 16)
    bad = Frame(robot="poisoned", sequence=2, time_s=2.0, odometry=Pose(x=1e300), ranges=[1.0] * 16)
    try:
        api.method("PublishFrames")(Request(frames=[good, bad]), timeout=DEADLINE_S)
    except grpc.RpcError as error:
        expect(error.code() == grpc.StatusCode.INVALID_ARGUMENT, f"{error.code()}")
        expect("frames[1].odometry.x" in error.details(), error.details())
        return error.details()
    raise AssertionError("the frame was accepted")


@check("bytes that are no protobuf: INTERNAL, as gRPC's status codes say of a request that does not parse")
def undecodable(channel):
    raw = channel.unary_unary(f"/{MAP_SERVICE}/CreateMap")
    try:
        # Field 1 (a string) sent as a varint.
        raw(b"\x08\x01", timeout=DEADLINE_S)
    except grpc.RpcError as error:
        expect(error.code() == grpc.StatusCode.INTERNAL, f"{error.code()}: {error.details()}")
        return error.details()
    raise AssertionError("garbage was accepted")


@check("silent sockets past --max-connections: fresh clients served within 1 s")
def silent_sockets(api, target):
    host, port = target.rsplit(":", 1)
    silent = [socket.create_connection((host, int(port))) for _ in range(40)]
    time.sleep(0.5)
    slowest = 0.0
    for _ in range(5):
        channel = own_channel(target)
        asked = time.monotonic()
        api.method("ListMaps", channel)(api.message("ListMapsRequest")(), timeout=DEADLINE_S)
        slowest = max(slowest, time.monotonic() - asked)
        channel.close()
        silent.extend(socket.create_connection((host, int(port))) for _ in range(8))
    for s in silent:
        s.close()
    expect(slowest < 1.0, f"the slowest call took {slowest:.2f} s")
    return f"slowest of 5 calls {slowest * 1000:.0f} ms beside {len(silent)} silent sockets"


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("target")
    parser.add_argument("--batches", type=int, default=100_000)
    args = parser.parse_args()
    channel = own_channel(args.target)
    grpc.channel_ready_future(channel).result(timeout=DEADLINE_S)
    api = Api(channel)
    reflection(api, channel)
    health(channel)
    pipelined(api, args.batches)
    unread_streams(api, args.target)
    poisoned_frame(api)
    undecodable(channel)
    silent_sockets(api, args.target)
    failed = RESULTS.count(False)
    print(f"{len(RESULTS) - failed} of {len(RESULTS)} checks passed", flush=True)
    sys.exit(failed)


if __name__ == "__main__":
    main()
