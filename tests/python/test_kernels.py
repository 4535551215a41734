"""The dense products' kernel (issue #25): the daemon names it, and the portable build's answers
are the dispatched kernel's — the same verdicts, points within float rounding."""

import numpy as np

import animspace


def _poses(client, demo_arm_transforms):
    """Key values of the demo arm posed along its animation (arm-animspace, which arm-pmsc was
    trained on), some pushed off the subspace by growing amounts: verdicts across hit and miss."""
    keys = client.describe_key_points("arm-pmsc")
    poses = []
    for i in range(24):
        frame = client.evaluate_skeleton_pose("arm-animspace", demo_arm_transforms(i / 24)).points[keys.indices]
        poses.append(frame + np.float32(0.002 * (i % 6)))
    return poses


def test_the_daemon_names_its_kernel_and_batching(client):
    info = client.server_info()
    assert info.kernel.startswith("openblas:") and len(info.kernel) > len("openblas:")
    assert info.max_batch_size == 64 and info.batch_delay_us == 0  # animspaced --help's defaults


def test_the_portable_kernel_gives_the_dispatched_kernels_answers(client, spawn_daemon, demo_arm_transforms):
    with animspace.Client(spawn_daemon("--kernel", "portable", "--max-batch-size", "8")) as portable:
        portable.wait_until_serving(deadline_s=60)  # its models load after the port opens
        info = portable.server_info()
        assert info.kernel.startswith("eigen:") and info.max_batch_size == 8
        poses = _poses(client, demo_arm_transforms)
        dispatched = client.evaluate_key_points("arm-pmsc", np.stack(poses))
        baseline = portable.evaluate_key_points("arm-pmsc", np.stack(poses))
        assert len({r.status for r in dispatched}) > 1, "the poses should not all get one verdict"
        for d, b in zip(dispatched, baseline):
            assert d.status == b.status
            assert abs(d.key_point_error - b.key_point_error) <= 1e-6 * max(1.0, d.key_point_error)
            # Two kernels sum in different orders: float rounding of each value's sum, far below
            # 1e-5 of the arm's extent (pmsc::reconstruction_rounding_bound).
            np.testing.assert_allclose(d.points, b.points, rtol=0, atol=1e-5 * max(1.0, float(np.abs(b.points).max())))
