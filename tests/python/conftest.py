"""Fixtures: a real animspaced on an ephemeral port, serving the bundled demo repository."""
import atexit
import contextlib
import math
import os
import pathlib
import shutil
import signal
import subprocess
import tempfile
import time

import grpc
import numpy as np
import pytest

BUILD = pathlib.Path(os.environ.get("ANIMSPACE_BUILD", pathlib.Path(__file__).resolve().parents[2] / "build"))


_demo_repository = None


def demo_repository_copy(work):
    """A private copy of the bundled demo repository under `work`. The demo is generated once per
    test session (`animspace demo-repository`, the daemon's own generator) and copied for each
    daemon, which may publish versions into it: generating it per daemon (the Cornell box's gathers
    and training) was most of the Python suite's time under the sanitizers. Starting without
    --model-repository, which generates it in the daemon, is tested by DaemonStartup in C++."""
    global _demo_repository
    if _demo_repository is None:
        generated = pathlib.Path(tempfile.mkdtemp(prefix="animspace-demo-")) / "repository"
        subprocess.run([str(BUILD / "bin" / "animspace"), "demo-repository", str(generated)], check=True,
                       stdout=subprocess.DEVNULL, timeout=600)
        atexit.register(shutil.rmtree, generated.parent, ignore_errors=True)
        _demo_repository = generated
    copy = work / "demo-repository"
    shutil.copytree(_demo_repository, copy)
    return copy


@contextlib.contextmanager
def run_animspaced(work, *arguments):
    """An animspaced on an ephemeral port (more `arguments` after --listen/--port-file), yielding its
    address; SIGTERM at the end, which must exit 0. `work` holds the port file and the log. Without
    --model-repository it serves a copy of the bundled demo (demo_repository_copy)."""
    if "--model-repository" not in arguments:
        arguments = ("--model-repository", str(demo_repository_copy(work)), *arguments)
    if "--poll-interval-s" not in arguments:
        # A test decides when its daemon sees new versions: no repository poll unless it asks.
        arguments = (*arguments, "--poll-interval-s", "0")
    port_file = work / "port"
    log = open(work / "animspaced.log", "w")
    process = subprocess.Popen(
        [str(BUILD / "bin" / "animspaced"), "--listen", "127.0.0.1:0", "--port-file", str(port_file), *arguments],
        stdout=log, stderr=subprocess.STDOUT)
    # Generous: a sanitized build loads the demo's models several times slower.
    deadline = time.time() + 180
    while not (port_file.exists() and port_file.read_text().strip()):
        if process.poll() is not None or time.time() > deadline:
            process.kill()
            pytest.fail("animspaced did not start: " + (work / "animspaced.log").read_text())
        time.sleep(0.02)
    address = "127.0.0.1:" + port_file.read_text().strip()
    try:
        yield address
    finally:
        process.send_signal(signal.SIGTERM)
        assert process.wait(timeout=15) == 0
        log.close()


@pytest.fixture(scope="session")
def daemon(tmp_path_factory):
    with run_animspaced(tmp_path_factory.mktemp("animspaced")) as address:
        yield address


@pytest.fixture()
def spawn_daemon(tmp_path_factory):
    """A factory for private daemons (their own flags, state a test may change): spawn(*flags) →
    address. Every daemon it started is stopped when the test ends."""
    with contextlib.ExitStack() as stack:
        def spawn(*arguments):
            return stack.enter_context(run_animspaced(tmp_path_factory.mktemp("animspaced-private"), *arguments))
        yield spawn


@pytest.fixture()
def channel(daemon):
    with grpc.insecure_channel(daemon) as channel:
        grpc.channel_ready_future(channel).result(timeout=10)
        yield channel


@pytest.fixture()
def client(daemon):
    """An animspace.Client on the session daemon, once the demo repository is loaded."""
    import animspace

    with animspace.Client(daemon) as client:
        client.wait_until_serving(deadline_s=30)
        yield client


def _rotation(axis, angle):
    c, s = math.cos(angle), math.sin(angle)
    i, j = {"x": (1, 2), "y": (2, 0), "z": (0, 1)}[axis]
    R = np.eye(4)
    R[i, i], R[i, j], R[j, i], R[j, j] = c, -s, s, c
    return R


def _arm_transforms(elbow_rad=0.0, shoulder_rad=0.0, twist_rad=0.0):
    # core/demo/bending_arm.h, restated independently of the client: arm-animspace's bones are a
    # fixed root, the upper arm and the forearm; G_upper = Ry(shoulder) and
    # G_fore = G_upper · T(elbow at x = 1) · Rz(elbow) · Rx(twist).
    upper = _rotation("y", shoulder_rad)
    elbow = np.eye(4)
    elbow[0, 3] = 1.0
    return np.stack([np.eye(4), upper, upper @ elbow @ _rotation("z", elbow_rad) @ _rotation("x", twist_rad)])


def _demo_arm_transforms(phase):
    # The demo animation (bending_arm.h demo_pose): frame f of 120 is phase f / 120; the models
    # were trained on the even frames.
    a = 2 * math.pi * phase
    return _arm_transforms(math.radians(130) * 0.5 * (1 - math.cos(a)), math.radians(15) * math.sin(a),
                           math.radians(25) * math.sin(2 * a))


@pytest.fixture()
def arm_transforms():
    """(elbow_rad, shoulder_rad, twist_rad) → arm-animspace's global bone transforms, 3×4×4 float64."""
    return _arm_transforms


@pytest.fixture()
def demo_arm_transforms():
    """phase → the demo animation's global bone transforms (3×4×4 float64); frame f is f / 120."""
    return _demo_arm_transforms
