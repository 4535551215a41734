"""Fixtures: a real animspaced on an ephemeral port, serving the bundled demo repository."""
import os
import pathlib
import signal
import subprocess
import time

import grpc
import pytest

BUILD = pathlib.Path(os.environ.get("ANIMSPACE_BUILD", pathlib.Path(__file__).resolve().parents[2] / "build"))


@pytest.fixture(scope="session")
def daemon(tmp_path_factory):
    work = tmp_path_factory.mktemp("animspaced")
    port_file = work / "port"
    log = open(work / "animspaced.log", "w")
    process = subprocess.Popen(
        [str(BUILD / "bin" / "animspaced"), "--listen", "127.0.0.1:0", "--port-file", str(port_file)],
        stdout=log, stderr=subprocess.STDOUT)
    deadline = time.time() + 30
    while not (port_file.exists() and port_file.read_text().strip()):
        if process.poll() is not None or time.time() > deadline:
            process.kill()
            pytest.fail("animspaced did not start: " + (work / "animspaced.log").read_text())
        time.sleep(0.02)
    address = "127.0.0.1:" + port_file.read_text().strip()
    yield address
    process.send_signal(signal.SIGTERM)
    assert process.wait(timeout=15) == 0


@pytest.fixture()
def channel(daemon):
    with grpc.insecure_channel(daemon) as channel:
        grpc.channel_ready_future(channel).result(timeout=10)
        yield channel
