"""Admin RPCs, bearer tokens and TLS, each on a private daemon (their state or flags are their own)."""
import shutil
import subprocess

import grpc
import numpy as np
import pytest

import animspace


def test_unload_load_and_retrain_with_a_logged_miss(spawn_daemon, arm_transforms):
    with animspace.Client(spawn_daemon()) as client:
        client.wait_until_serving()
        client.unload_model("arm-pmsc")
        with pytest.raises(animspace.NotFound):
            client.describe_key_points("arm-pmsc")
        assert "arm-pmsc" not in [m.name for m in client.list_models()]
        loaded = client.load_model("arm-pmsc")
        assert loaded.name == "arm-pmsc" and loaded.default_version == 1 and loaded.default.state == "AVAILABLE"
        with pytest.raises(animspace.NotFound):
            client.load_model("no-such-model")

        keys = client.describe_key_points("arm-pmsc")
        dry = client.retrain("arm-pmsc", dry_run=True, deadline_s=120)
        assert dry.new_version == 0 and dry.misses_used == 0
        assert dry.training_frames == client.describe_model("arm-pmsc").default.frame_count
        assert dry.basis_size >= 1 and dry.key_point_count >= 1 and dry.condition_number >= 1
        # Nothing logged yet: the dry run says a retrain would change nothing, and a real one is refused.
        assert dry.unchanged and (dry.epsilon_min, dry.hit_rate) == (dry.previous_epsilon_min, dry.previous_hit_rate)
        with pytest.raises(animspace.FailedPrecondition, match="nothing new to train on"):
            client.retrain("arm-pmsc", deadline_s=120)
        assert client.describe_model("arm-pmsc").default_version == 1

        # A miss completed by the client is logged, and the next retrain folds it in.
        full = client.evaluate_skeleton_pose("arm-animspace", arm_transforms(2.9)).points
        verdict = client.evaluate_key_points("arm-pmsc", full[keys.indices])
        assert verdict.full_evaluation_needed
        assert client.complete_miss("arm-pmsc", full[keys.indices], full, version=verdict.model_version).logged
        retrained = client.retrain("arm-pmsc", deadline_s=120)
        assert retrained.new_version == 2 and retrained.misses_used >= 1 and not retrained.unchanged

        assert client.describe_model("arm-pmsc").default_version == 2
        assert client.describe_key_points("arm-pmsc").model_version == 2
        # A caller pinned to version 1 keeps its key points (and its answers) across the swap.
        pinned = client.evaluate_key_points("arm-pmsc", full[keys.indices], version=keys.model_version)
        assert pinned.model_version == 1
        with pytest.raises(animspace.FailedPrecondition):
            client.retrain("arm-animspace", dry_run=True)


def test_bearer_tokens_and_admin_tokens(spawn_daemon, tmp_path):
    (tmp_path / "users").write_text("# user tokens\nuser-secret\n")
    (tmp_path / "admins").write_text("admin-secret\n")
    address = spawn_daemon("--auth-token-file", str(tmp_path / "users"),
                           "--admin-token-file", str(tmp_path / "admins"))
    with animspace.Client(address) as anonymous:
        anonymous.wait_until_serving()  # health needs no token
        for call in (anonymous.list_models, lambda: anonymous.get_lod("arm-animspace", level=2),
                     lambda: list(anonymous.stream_key_points("arm-pmsc", [np.zeros((24, 3))]))):
            with pytest.raises(animspace.Unauthenticated) as error:
                call()
            assert error.value.code == grpc.StatusCode.UNAUTHENTICATED
    with animspace.Client(address, token="not-the-secret") as stranger:
        with pytest.raises(animspace.Unauthenticated):
            stranger.list_models()
    with animspace.Client(address, token="user-secret") as user:
        assert user.metadata == (("authorization", "Bearer user-secret"),)
        assert len(user.list_models()) == 8
        assert user.get_lod("arm-animspace", level=2).vertex_count > 0
        for admin_only in (lambda: user.unload_model("arm"), lambda: user.stats(reset=True),
                           lambda: user.retrain("arm-pmsc", dry_run=True)):
            with pytest.raises(animspace.PermissionDenied):
                admin_only()
    with animspace.Client(address, token="admin-secret") as admin:
        assert admin.stats(reset=True).models
        assert admin.load_model("arm").default_version == 1
    with pytest.raises(ValueError, match="token"):
        animspace.Client(address, token="two\nlines")


def _openssl(*arguments, cwd):
    subprocess.run(["openssl", *arguments], cwd=cwd, check=True, capture_output=True)


def _certificate(cwd, name, subject, extension):
    _openssl("req", "-newkey", "ec", "-pkeyopt", "ec_paramgen_curve:prime256v1", "-nodes", "-keyout", f"{name}.key",
             "-out", f"{name}.csr", "-subj", subject, cwd=cwd)
    (cwd / f"{name}.ext").write_text(extension + "\n")
    _openssl("x509", "-req", "-in", f"{name}.csr", "-CA", "ca.pem", "-CAkey", "ca.key", "-CAcreateserial",
             "-out", f"{name}.pem", "-days", "2", "-extfile", f"{name}.ext", cwd=cwd)


@pytest.mark.skipif(shutil.which("openssl") is None, reason="needs the openssl command to make test certificates")
def test_mutual_tls_with_a_server_name_override(spawn_daemon, tmp_path):
    _openssl("req", "-x509", "-newkey", "ec", "-pkeyopt", "ec_paramgen_curve:prime256v1", "-nodes", "-keyout",
             "ca.key", "-out", "ca.pem", "-days", "2", "-subj", "/CN=animspace test CA", cwd=tmp_path)
    _certificate(tmp_path, "server", "/CN=animspace.test", "subjectAltName=DNS:animspace.test")
    _certificate(tmp_path, "client", "/CN=animspace test client", "extendedKeyUsage=clientAuth")
    address = spawn_daemon("--tls-cert", str(tmp_path / "server.pem"), "--tls-key", str(tmp_path / "server.key"),
                           "--tls-client-ca", str(tmp_path / "ca.pem"))
    ca = (tmp_path / "ca.pem").read_bytes()
    # The address is 127.0.0.1; the certificate names animspace.test.
    with animspace.Client(address, root_certificates=ca, client_certificate=(tmp_path / "client.pem").read_text(),
                          client_key=(tmp_path / "client.key").read_bytes(), server_name="animspace.test") as client:
        client.wait_until_serving()
        assert len(client.list_models()) == 8
    refused = [
        animspace.Client(address, deadline_s=5),  # plaintext
        animspace.Client(address, root_certificates=ca, server_name="animspace.test", deadline_s=5),  # no client cert
        animspace.Client(address, root_certificates=ca, client_certificate=(tmp_path / "client.pem").read_bytes(),
                         client_key=(tmp_path / "client.key").read_bytes(), server_name="other.test", deadline_s=5),
    ]
    for client in refused:
        with client, pytest.raises(animspace.Unavailable):
            client.list_models()
    with pytest.raises(ValueError, match="both or neither"):
        animspace.Client(address, client_certificate=b"x")
