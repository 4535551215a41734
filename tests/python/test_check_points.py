"""Check points through the Python client (issue #35): the client poses them like key points and
sends them; the server measures e_check there, and a HIT the key points alone give becomes BLEND
or MISS when the check points disagree. A model without check points refuses check values and
serves as before.

Expected values are computed here from what the server returns (e_check as the largest distance
between the estimate and the sent check values, the verdict from ε), never taken from the client.
"""
import pathlib
import shutil

import numpy as np
import pytest

import animspace

# arm-pmsc-engine's soft cache was trained on arm-animspace's poses (same points), so a demo
# frame posed by arm-animspace is one of its training frames.
MODEL = "arm-pmsc-engine"
RELEASE_PMSC = pathlib.Path(__file__).resolve().parents[1] / "fixtures" / "release-0.1" / "pmsc.anim"


def posed_arm(client, transforms):
    return client.evaluate_skeleton_pose("arm-animspace", transforms).points


def e_check(estimate, checks, keys):
    """max over check points of ‖f_c − f̂_c‖, from the returned estimate f̂."""
    return float(np.linalg.norm(estimate[keys.check_point_indices].astype(np.float64) - checks, axis=1).max())


@pytest.fixture()
def trained_pose(client, demo_arm_transforms):
    keys = client.describe_key_points(MODEL)
    assert keys.check_point_count > 0, "the demo's PMSC models are trained with check points"
    return keys, posed_arm(client, demo_arm_transforms(14 / 120))  # a training frame


def test_describe_key_points_lists_check_points_apart_from_the_key_points(client, trained_pose):
    keys, _ = trained_pose
    C = keys.check_point_count
    assert keys.check_point_indices.dtype == np.uint32 and keys.check_point_indices.shape == (C,)
    assert not set(keys.check_point_indices.tolist()) & set(keys.indices.tolist())
    assert len(set(keys.check_point_indices.tolist())) == C
    assert int(keys.check_point_indices.max()) < keys.control_point_count
    assert keys.check_point_regions.shape == ((C,) if keys.regions.size else (0,))
    version = client.describe_model(MODEL).default
    assert version.check_point_count == C
    assert version.calibration_statement
    # What the guarantee rests on (issue #52): real over-tolerance frames among its samples.
    assert 0 <= version.calibration_real_bad_samples <= version.calibration_bad_samples
    assert f"the other {version.calibration_bad_samples - version.calibration_real_bad_samples}" in \
        version.calibration_statement or "none of them from a held-out frame" in version.calibration_statement


def test_check_values_far_off_overturn_the_hit_of_exact_key_values(client, trained_pose):
    keys, full = trained_pose
    model = client.describe_model(MODEL).default
    pose = keys.pose(full)
    np.testing.assert_array_equal(pose.key_values, full[keys.indices])
    np.testing.assert_array_equal(pose.check_values, full[keys.check_point_indices])

    alone = client.evaluate_key_points(MODEL, pose.key_values)
    assert alone.status == "HIT" and not alone.checked
    # The key term alone: the worst key's residual (issue #52), at least the RMS e_key.
    assert alone.check_point_error == 0 and alone.error_estimate == alone.key_point_max_error
    assert alone.key_point_max_error >= alone.key_point_error

    checked = client.evaluate_key_points(MODEL, pose.key_values, check_values=pose.check_values)
    assert checked.checked and checked.key_point_error == alone.key_point_error
    # Without a skeleton pose the points are the estimate f̂ whatever the verdict.
    assert checked.status == "HIT" or checked.full_evaluation_needed
    assert checked.check_point_error == pytest.approx(e_check(checked.points, pose.check_values, keys),
                                                      rel=1e-3, abs=1e-6)
    # e = max(w·e_key, e_check): never below e_check, and the verdict is e against ε.
    assert checked.error_estimate >= checked.check_point_error * (1 - 1e-6)
    assert (checked.status == "HIT") == (checked.error_estimate <= model.epsilon_min)

    # The same exact key values with the check points moved by half a unit (the arm is two units
    # long; ε_max is a few hundredths): e_check ≥ 0.5 − e_check(exact), far above ε_max.
    off = pose.check_values + np.float32([0.5, 0, 0])
    overturned = client.evaluate_key_points(MODEL, pose.key_values, check_values=off)
    assert overturned.status == "MISS" and overturned.checked and overturned.blend_weight == 1
    assert overturned.check_point_error == pytest.approx(e_check(overturned.points, off, keys), rel=1e-3)
    assert overturned.check_point_error > model.epsilon_max
    assert overturned.key_point_error == alone.key_point_error  # the projection never sees check values
    assert overturned.full_evaluation_needed

    # A batch: each pose's check values travel with it.
    batch = client.evaluate_key_points(MODEL, np.stack([pose.key_values] * 3),
                                       check_values=np.stack([pose.check_values, off, pose.check_values]))
    assert [r.status for r in batch] == [checked.status, "MISS", checked.status]
    assert all(r.checked for r in batch)


def test_streams_and_complete_miss_carry_the_check_values(client, trained_pose):
    keys, full = trained_pose
    pose = keys.pose(full)
    off = pose.check_values + np.float32([0.5, 0, 0])
    frames = [animspace.KeyPointPose(pose.key_values, check_values=off), pose.key_values]
    streamed = list(client.stream_key_points(MODEL, frames, omit_points=True))
    assert [(r.status, r.checked) for r in streamed] == [("MISS", True), ("HIT", False)]

    # CompleteMiss repeats the verdict of the check values it is sent: a MISS answers f itself —
    # the full pose those check values were read from (f moved at the check points).
    moved = full.copy()
    moved[keys.check_point_indices] = off
    completion = client.complete_miss(MODEL, pose.key_values, moved, check_values=off)
    assert completion.result.status == "MISS" and completion.result.checked and completion.logged
    np.testing.assert_allclose(completion.result.points, moved, atol=1e-6)
    unchecked = client.complete_miss(MODEL, pose.key_values, full)
    assert unchecked.result.status == "HIT" and not unchecked.logged
    # Full values that are not the pose of the check values are refused, naming the check point.
    with pytest.raises(animspace.InvalidArgument, match="full_values: check point 0"):
        client.complete_miss(MODEL, pose.key_values, full, check_values=off)


def test_a_wrong_check_value_count_is_invalid_argument_naming_the_field(client, trained_pose):
    keys, full = trained_pose
    pose = keys.pose(full)
    C = keys.check_point_count
    with pytest.raises(animspace.InvalidArgument) as refused:
        client.evaluate_key_points(MODEL, pose.key_values, check_values=pose.check_values[:-1])
    assert f"poses[0].check_values.point_count: expected {C} check points, got {C - 1}" in refused.value.message
    with pytest.raises(ValueError, match="check_values"):  # the client's own shape check: nothing sent
        client.evaluate_key_points(MODEL, pose.key_values, check_values=pose.check_values.ravel())


def test_a_model_without_check_points_refuses_check_values_and_serves_as_before(spawn_daemon, tmp_path):
    repository = tmp_path / "repository"
    (repository / "old-pmsc" / "1").mkdir(parents=True)
    shutil.copy(RELEASE_PMSC, repository / "old-pmsc" / "1" / "model.anim")
    with animspace.Client(spawn_daemon("--model-repository", str(repository))) as old:
        old.wait_until_serving(deadline_s=30)
        keys = old.describe_key_points("old-pmsc")
        assert keys.check_point_count == 0
        version = old.describe_model("old-pmsc").default
        assert version.check_point_count == 0 and not version.calibration_guarantee_holds
        assert version.calibration_statement.startswith("no guarantee")
        values = np.zeros((keys.count, keys.channel_count), np.float32)
        result = old.evaluate_key_points("old-pmsc", values)
        assert not result.checked and result.error_estimate == result.key_point_error
        # A full frame's pose of such a model has no check values to send.
        frame = np.zeros((keys.control_point_count, keys.channel_count), np.float32)
        assert keys.pose(frame).check_values.shape == (0, keys.channel_count)
        assert not old.evaluate_key_points("old-pmsc", values, check_values=keys.pose(frame).check_values).checked
        with pytest.raises(animspace.InvalidArgument) as refused:
            old.evaluate_key_points("old-pmsc", values, check_values=np.zeros((1, keys.channel_count)))
        assert "poses[0].check_values: model 'old-pmsc' version 1 has no check points" in refused.value.message
