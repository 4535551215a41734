"""deploy/: every manifest parses and lints, and the container image, the compose file, the systemd
units and the Kubernetes manifests agree with each other and with the programs they run: every
flag and subcommand exists in the programs' --help, and ports, probes, images, volumes and miss-log
directories line up. No Docker engine or cluster is needed; nothing here is built or applied."""
import functools
import json
import os
import pathlib
import re
import shlex
import shutil
import subprocess
import tempfile

import pytest

yaml = pytest.importorskip("yaml", reason="python3-yaml is not installed (scripts/install-deps.sh installs it)")

ROOT = pathlib.Path(__file__).resolve().parents[2]
DEPLOY = ROOT / "deploy"
BUILD = pathlib.Path(os.environ.get("ANIMSPACE_BUILD", ROOT / "build"))
PROGRAMS = ("animspaced", "animspace", "animspace-loadtest")
IMAGE = "animspace:latest"
# Shell words that may stand before a command on a line of a script.
SHELL_KEYWORDS = {"then", "do", "else", "elif", "if", "while", "until", "exec", "!", "{", "("}
SHELL_SEPARATORS = {";", ";;", "&&", "||", "|", "&", "(", ")"}


# ---------------------------------------------------------------------------------------------
# The programs' command lines, from their --help (CLI11's layout).


class Usage:
    """One program's (or subcommand's) options: name → whether it takes a value, positionals."""

    def __init__(self, help_text):
        self.options = {}
        self.positionals = []
        self.subcommands = set()
        section = None
        for line in help_text.splitlines():
            if re.match(r"^\S.*:$", line):
                section = line[:-1]
                continue
            if section == "Options":
                match = re.match(r"^\s+(?:(-\w),)?(--[\w-]+)(?:\s+(\S+))?", line)
                if match:
                    # A value-taking option shows its type (TEXT, INT, UINT, FLOAT, ...) after its name.
                    takes_value = bool(match.group(3)) and re.match(r"^[A-Z]+\b", match.group(3)) is not None
                    for name in filter(None, (match.group(1), match.group(2))):
                        self.options[name] = takes_value
            elif section == "Positionals":
                match = re.match(r"^\s+([\w-]+)\s", line)
                if match:
                    self.positionals.append(match.group(1))
            elif section == "Subcommands":
                match = re.match(r"^\s+([\w-]+)\s", line)
                if match:
                    self.subcommands.add(match.group(1))

    def consume(self, arguments, where, stop_at_positional=False):
        """Checks `arguments` against these options; returns the arguments that are not options
        or option values (positionals). With `stop_at_positional` the first positional (a
        subcommand) ends the options: it and everything after it are returned as they are."""
        rest = []
        i = 0
        while i < len(arguments):
            token = arguments[i]
            if stop_at_positional and not token.startswith("-"):
                return arguments[i:]
            if token.startswith("-") and token != "-":
                name, has_inline_value = token.split("=", 1)[0], "=" in token
                assert name in self.options, f"{where}: {name} is not an option ({sorted(self.options)})"
                if self.options[name] and not has_inline_value:
                    assert i + 1 < len(arguments) and not arguments[i + 1].startswith("--"), \
                        f"{where}: {name} needs a value"
                    i += 1
                elif not self.options[name]:
                    assert not has_inline_value, f"{where}: {name} takes no value"
            else:
                rest.append(token)
            i += 1
        return rest


def binary(program):
    path = (BUILD / "bin" / program).resolve()  # systemd wants absolute paths; ANIMSPACE_BUILD may be relative
    if not path.exists():
        pytest.skip(f"{path} is not built")
    return path


@functools.lru_cache(maxsize=None)
def usage(*command):
    """The Usage of `program [subcommand] --help`."""
    result = subprocess.run([str(binary(command[0])), *command[1:], "--help"], capture_output=True, text=True,
                            timeout=30)
    assert result.returncode == 0, f"{' '.join(command)} --help failed: {result.stderr}"
    return Usage(result.stdout)


def check_invocation(program, arguments, where):
    """Every option, value and subcommand of one command line exists in the program's --help."""
    where = f"{where}: {program} {' '.join(arguments)}"
    if program == "animspace":
        top = usage("animspace")
        rest = top.consume(arguments, where, stop_at_positional=True)
        assert rest, f"{where}: no subcommand"
        subcommand = rest[0]
        assert subcommand in top.subcommands, \
            f"{where}: `animspace {subcommand}` is not a subcommand of this build ({sorted(top.subcommands)})"
        sub = usage("animspace", subcommand)
        positionals = sub.consume(rest[1:], where)
        assert len(positionals) <= len(sub.positionals), f"{where}: unexpected arguments {positionals}"
    else:
        positionals = usage(program).consume(arguments, where)
        assert not positionals, f"{where}: {program} takes no positional arguments, got {positionals}"


def option_values(arguments, option):
    """The values given to `option` in an argument list (`--x v` or `--x=v`)."""
    values = []
    for i, token in enumerate(arguments):
        if token == option and i + 1 < len(arguments):
            values.append(arguments[i + 1])
        elif token.startswith(option + "="):
            values.append(token.split("=", 1)[1])
    return values


def option_value(arguments, option):
    values = option_values(arguments, option)
    assert len(values) == 1, f"{option} given {len(values)} times in {arguments}"
    return values[0]


def port_of(address):
    host, _, port = address.rpartition(":")
    assert host and port.isdigit(), f"not host:port: {address!r}"
    return int(port)


def is_program(word):
    return pathlib.PurePosixPath(word).name in PROGRAMS


def script_invocations(script):
    """(program, arguments) of every command of a shell script whose command word is one of ours."""
    script = re.sub(r"\\\n", " ", script)
    found = []
    for line in script.splitlines():
        lexer = shlex.shlex(line, posix=True, punctuation_chars=True)
        lexer.whitespace_split = True
        lexer.commenters = "#"
        words = list(lexer)
        segments, segment = [], []
        for word in words:
            if word in SHELL_SEPARATORS:
                segments.append(segment)
                segment = []
            else:
                segment.append(word)
        segments.append(segment)
        for segment in segments:
            while segment and (segment[0] in SHELL_KEYWORDS or re.match(r"^\w+=", segment[0])):
                segment = segment[1:]
            if segment and is_program(segment[0]):
                found.append((pathlib.PurePosixPath(segment[0]).name, segment[1:]))
    return found


def argv_invocations(argv):
    """An exec-form command line: our program directly, or a shell running a script."""
    if not argv:
        return []
    if pathlib.PurePosixPath(argv[0]).name in ("sh", "bash") and "-c" in argv:
        return script_invocations(argv[argv.index("-c") + 1])
    if is_program(argv[0]):
        return [(pathlib.PurePosixPath(argv[0]).name, list(argv[1:]))]
    return []


# ---------------------------------------------------------------------------------------------
# The deployment files.


def yaml_files():
    return sorted(p for p in DEPLOY.rglob("*") if p.suffix in (".yaml", ".yml") and p.is_file())


def load_all(path):
    return [document for document in yaml.safe_load_all(path.read_text()) if document is not None]


@functools.lru_cache(maxsize=None)
def kubernetes_objects():
    objects = []
    for path in sorted((DEPLOY / "kubernetes").glob("*.yaml")):
        if path.name == "kustomization.yaml":
            continue
        objects += [(path.name, document) for document in load_all(path)]
    return objects


def objects_of(kind):
    return [document for _, document in kubernetes_objects() if document["kind"] == kind]


def only(kind):
    found = objects_of(kind)
    assert len(found) == 1, f"expected one {kind}, found {len(found)}"
    return found[0]


def workload(name):
    (deployment,) = [d for d in objects_of("Deployment") if d["metadata"]["name"] == name]
    return deployment


def daemon_deployment():
    """The Deployment whose container runs animspaced (the image's entrypoint)."""
    found = [d for d in objects_of("Deployment")
             if any(c["image"] == IMAGE for c in d["spec"]["template"]["spec"]["containers"])]
    assert len(found) == 1, "expected one Deployment running animspace:latest"
    return found[0]


def pod_spec(obj):
    if obj["kind"] == "CronJob":
        return obj["spec"]["jobTemplate"]["spec"]["template"]["spec"]
    return obj["spec"]["template"]["spec"]


def daemon_container(deployment):
    (container,) = [c for c in pod_spec(deployment)["containers"] if c["image"] == IMAGE]
    return container


@functools.lru_cache(maxsize=None)
def dockerfile():
    """The Dockerfile's instructions, continuations joined: [(INSTRUCTION, rest)], and its stages."""
    text = re.sub(r"\\\n", " ", (DEPLOY / "container" / "Dockerfile").read_text())
    instructions = []
    for line in text.splitlines():
        if line.strip() and not line.lstrip().startswith("#"):
            keyword, _, rest = line.strip().partition(" ")
            instructions.append((keyword.upper(), rest.strip()))
    return instructions


def dockerfile_runtime():
    """Instructions of the last stage (the image that ships)."""
    instructions = dockerfile()
    last_from = max(i for i, (keyword, _) in enumerate(instructions) if keyword == "FROM")
    return instructions[last_from:]


def exec_form(rest):
    assert rest.startswith("["), f"use the exec form (JSON array), got {rest}"
    return yaml.safe_load(rest)


def image_entrypoint():
    (entrypoint,) = [exec_form(rest) for keyword, rest in dockerfile_runtime() if keyword == "ENTRYPOINT"]
    return entrypoint


def image_cmd():
    (cmd,) = [exec_form(rest) for keyword, rest in dockerfile_runtime() if keyword == "CMD"]
    return cmd


def container_argv(container, default_entrypoint):
    """What a Kubernetes container runs: command (or the image's entrypoint) + args."""
    return list(container.get("command", default_entrypoint)) + list(container.get("args", []))


def pod_containers(obj):
    spec = pod_spec(obj)
    return spec.get("initContainers", []) + spec["containers"]


@functools.lru_cache(maxsize=None)
def compose():
    return yaml.safe_load((DEPLOY / "compose" / "compose.yaml").read_text())


def compose_argv(service):
    """A compose service's command line, with compose's `$$` escape undone."""
    entrypoint = service.get("entrypoint", image_entrypoint())
    command = service.get("command", image_cmd() if "entrypoint" not in service else [])
    if isinstance(entrypoint, str):
        entrypoint = shlex.split(entrypoint)
    if isinstance(command, str):
        command = shlex.split(command)
    return [word.replace("$$", "$") for word in list(entrypoint) + list(command)]


def systemd_unit(name):
    """{section: [(key, value)]}; continuation lines joined."""
    text = re.sub(r"\\\n", " ", (DEPLOY / "systemd" / name).read_text())
    sections, section = {}, None
    for line in text.splitlines():
        line = line.strip()
        if not line or line.startswith(("#", ";")):
            continue
        if line.startswith("["):
            section = sections.setdefault(line.strip("[]"), [])
        else:
            key, _, value = line.partition("=")
            section.append((key.strip(), value.strip()))
    return sections


def unit_values(unit, section, key):
    return [value for k, value in unit[section] if k == key]


def exec_start(unit):
    return [shlex.split(value.lstrip("-@:+!")) for value in unit_values(unit, "Service", "ExecStart")]


@functools.lru_cache(maxsize=None)
def all_invocations():
    """(where, program, arguments) of every command line in deploy/ that runs one of our programs."""
    found = []
    # Dockerfile: the image's default command line and its health check.
    found += [("Dockerfile ENTRYPOINT+CMD", p, a) for p, a in argv_invocations(image_entrypoint() + image_cmd())]
    for keyword, rest in dockerfile_runtime():
        if keyword == "HEALTHCHECK":
            check = exec_form(rest.split(" CMD ", 1)[1])
            found += [("Dockerfile HEALTHCHECK", p, a) for p, a in argv_invocations(check)]
    # Compose: each service's command line and health check.
    for name, service in compose()["services"].items():
        found += [(f"compose {name}", p, a) for p, a in argv_invocations(compose_argv(service))]
        test = service.get("healthcheck", {}).get("test")
        if test:
            assert test[0] == "CMD", f"compose {name}: healthcheck should use the exec form"
            found += [(f"compose {name} healthcheck", p, a) for p, a in argv_invocations(test[1:])]
    # Kubernetes: every container of our image, init containers included.
    for file, obj in kubernetes_objects():
        if obj["kind"] in ("Deployment", "CronJob", "Job"):
            for container in pod_containers(obj):
                if container["image"] == IMAGE:
                    where = f"{file} {obj['metadata']['name']}/{container['name']}"
                    found += [(where, p, a) for p, a in argv_invocations(container_argv(container, image_entrypoint()))]
    # systemd: every ExecStart.
    for unit in sorted((DEPLOY / "systemd").glob("*.service")):
        for argv in exec_start(systemd_unit(unit.name)):
            found += [(unit.name, p, a) for p, a in argv_invocations(argv)]
    return found


def invocations_in(prefix, program, subcommand=None):
    found = [(where, a) for where, p, a in all_invocations() if where.startswith(prefix) and p == program]
    if subcommand:
        found = [(where, a) for where, a in found if subcommand in a]
    return found


def daemon_arguments(prefix):
    found = invocations_in(prefix, "animspaced")
    assert len(found) == 1, f"{prefix}: expected one animspaced command line, found {len(found)}"
    return found[0][1]


# ---------------------------------------------------------------------------------------------
# Syntax.


def test_every_yaml_file_parses_into_mappings():
    files = yaml_files()
    assert {p.relative_to(DEPLOY).parts[0] for p in files} >= {"compose", "kubernetes"}
    for path in files:
        documents = load_all(path)
        assert documents, f"{path}: empty"
        for document in documents:
            assert isinstance(document, dict), f"{path}: a document is not a mapping"
    for file, obj in kubernetes_objects():
        assert {"apiVersion", "kind", "metadata"} <= obj.keys(), f"{file}: not a Kubernetes object"
        assert obj["metadata"].get("name"), f"{file}: {obj['kind']} without a name"
    # The Envoy configuration is YAML inside a ConfigMap.
    assert "static_resources" in envoy_config()


def test_yamllint_passes():
    yamllint = shutil.which("yamllint")
    if yamllint is None:
        pytest.skip("yamllint is not installed (scripts/install-deps.sh installs it)")
    files = [str(p) for p in yaml_files()]
    result = subprocess.run([yamllint, "--strict", "-c", str(DEPLOY / ".yamllint"), *files],
                            capture_output=True, text=True, timeout=30)
    assert result.returncode == 0, result.stdout + result.stderr
    # The Envoy configuration embedded in the ConfigMap too.
    result = subprocess.run([yamllint, "--strict", "-c", str(DEPLOY / ".yamllint"), "-"],
                            input=envoy_config_text(), capture_output=True, text=True, timeout=30)
    assert result.returncode == 0, "envoy.yaml (ConfigMap data): " + result.stdout + result.stderr


def test_kustomization_lists_every_manifest_and_renders_into_one_namespace():
    kustomization = yaml.safe_load((DEPLOY / "kubernetes" / "kustomization.yaml").read_text())
    manifests = {p.name for p in (DEPLOY / "kubernetes").glob("*.yaml")} - {"kustomization.yaml"}
    assert sorted(kustomization["resources"]) == sorted(manifests)
    namespace = kustomization["namespace"]
    assert only("Namespace")["metadata"]["name"] == namespace
    assert {i["name"] for i in kustomization.get("images", [])} <= {IMAGE.split(":")[0]}
    kubectl = shutil.which("kubectl")
    if kubectl is None:
        return  # the file-level checks above still ran
    result = subprocess.run([kubectl, "kustomize", str(DEPLOY / "kubernetes")], capture_output=True, text=True,
                            timeout=30)
    assert result.returncode == 0, result.stderr
    rendered = [d for d in yaml.safe_load_all(result.stdout) if d]
    assert len(rendered) == len(kubernetes_objects())
    for obj in rendered:
        if obj["kind"] != "Namespace":
            assert obj["metadata"]["namespace"] == namespace, f"{obj['kind']} {obj['metadata']['name']}"
        for container in pod_containers(obj) if obj["kind"] in ("Deployment", "CronJob") else []:
            if container["name"] != "envoy":
                assert container["image"] == IMAGE


def test_systemd_units_verify():
    analyze = shutil.which("systemd-analyze")
    if analyze is None:
        pytest.skip("systemd-analyze is not installed")
    units = sorted((DEPLOY / "systemd").glob("animspace*"))
    assert {u.name for u in units} >= {"animspaced.service", "animspace-retrain.service", "animspace-retrain.timer"}
    with tempfile.TemporaryDirectory() as work:
        copies = []
        for unit in units:
            # The units name the installed binaries; verify against the build's.
            text = unit.read_text()
            for program in PROGRAMS:
                text = text.replace(f"/usr/local/bin/{program} ", f"{binary(program)} ")
            copy = pathlib.Path(work) / unit.name
            copy.write_text(text)
            copies.append(str(copy))
        result = subprocess.run([analyze, "verify", "--man=no", *copies], capture_output=True, text=True, timeout=30)
    # systemd-analyze only warns (exit 0) on unknown keys and bad values: any line about our
    # units is a defect.
    complaints = [line for line in (result.stdout + result.stderr).splitlines()
                  if any(unit.name in line for unit in units)]
    assert result.returncode == 0 and not complaints, result.stdout + result.stderr


# ---------------------------------------------------------------------------------------------
# Command lines against the programs.


def test_every_command_line_uses_existing_flags_and_subcommands():
    invocations = all_invocations()
    # Each place that should run our programs was found (else the check below proves nothing).
    for prefix, program, subcommand in [
        ("Dockerfile ENTRYPOINT", "animspaced", None), ("Dockerfile HEALTHCHECK", "animspace", "health"),
        ("compose animspaced", "animspaced", None), ("compose loadtest", "animspace-loadtest", None),
        ("compose retrain", "animspace", "retrain-offline"), ("compose seed-models", "animspace", "demo-repository"),
        ("deployment.yaml", "animspaced", None), ("cronjob.yaml", "animspace", "retrain-offline"),
        ("animspaced.service", "animspaced", None), ("animspace-retrain.service", "animspace", "retrain-offline"),
    ]:
        assert invocations_in(prefix, program, subcommand), f"no `{program} {subcommand or ''}` found in {prefix}"
    for where, program, arguments in invocations:
        check_invocation(program, arguments, where)


def test_the_checker_refuses_unknown_flags_and_subcommands():
    # The flag check above must be able to fail: a made-up flag, a value-taking flag without its
    # value and an unknown subcommand are refused.
    with pytest.raises(AssertionError, match="--no-such-flag"):
        check_invocation("animspaced", ["--listen", "0.0.0.0:50051", "--no-such-flag"], "probe")
    with pytest.raises(AssertionError, match="needs a value"):
        check_invocation("animspaced", ["--model-repository", "--listen", "0.0.0.0:1"], "probe")
    with pytest.raises(AssertionError, match="not a subcommand"):
        check_invocation("animspace", ["no-such-subcommand"], "probe")
    assert script_invocations('for m in $X; do animspace -s a:1 health || s=1; done') == \
        [("animspace", ["-s", "a:1", "health"])]


def test_retrain_reads_every_miss_log_and_writes_the_repository_the_daemons_serve():
    # Kubernetes: the CronJob's --repository / --miss-logs are the mounts of the claims the
    # Deployment serves from and logs to.
    deployment, cronjob = daemon_deployment(), only("CronJob")
    daemon = daemon_arguments("deployment.yaml")
    claims = {}
    for obj, role in ((deployment, "daemon"), (cronjob, "retrain")):
        spec = pod_spec(obj)
        volumes = {v["name"]: v for v in spec["volumes"]}
        for container in spec["containers"]:
            for mount in container.get("volumeMounts", []):
                claims[(role, mount["mountPath"])] = (volumes[mount["name"]], mount)
    (where, retrain), = invocations_in("cronjob.yaml", "animspace", "retrain-offline")
    models_daemon = claims[("daemon", option_value(daemon, "--model-repository"))]
    models_retrain = claims[("retrain", option_value(retrain, "--repository"))]
    misses_retrain = claims[("retrain", option_value(retrain, "--miss-logs"))]
    miss_dir = option_value(daemon, "--miss-log-dir")
    (misses_daemon,) = [v for (role, path), v in claims.items() if role == "daemon" and miss_dir.startswith(path + "/")]
    claim = lambda volume: volume["persistentVolumeClaim"]["claimName"]  # noqa: E731
    assert claim(models_daemon[0]) == claim(models_retrain[0])
    assert claim(misses_daemon[0]) == claim(misses_retrain[0])
    assert claim(models_daemon[0]) != claim(misses_daemon[0])
    # The replicas read the repository, the retrain publishes into it; the retrain reads the logs.
    assert models_daemon[1].get("readOnly") is True
    assert models_daemon[0]["persistentVolumeClaim"].get("readOnly") is True
    assert not models_retrain[1].get("readOnly") and not models_retrain[0]["persistentVolumeClaim"].get("readOnly")
    assert misses_retrain[1].get("readOnly") is True
    assert not misses_daemon[1].get("readOnly")
    # Both claims are shared by every replica and the CronJob's pod: ReadWriteMany.
    pvcs = {p["metadata"]["name"]: p for p in objects_of("PersistentVolumeClaim")}
    for name in (claim(models_daemon[0]), claim(misses_daemon[0])):
        assert pvcs[name]["spec"]["accessModes"] == ["ReadWriteMany"], name
    # Two retrains must not race for the same next version.
    assert cronjob["spec"]["concurrencyPolicy"] == "Forbid"
    # The daemon polls for the versions the CronJob publishes.
    assert float(option_value(daemon, "--poll-interval-s")) > 0


def test_each_replica_has_its_own_miss_log_directory():
    deployment = daemon_deployment()
    container = daemon_container(deployment)
    miss_dir = option_value(daemon_arguments("deployment.yaml"), "--miss-log-dir")
    # One writer per miss-log file: the directory is named after the pod (downward API).
    variables = re.findall(r"\$\((\w+)\)", miss_dir)
    assert variables, f"--miss-log-dir {miss_dir} is the same for every replica"
    env = {e["name"]: e for e in container.get("env", [])}
    for variable in variables:
        assert env[variable]["valueFrom"]["fieldRef"]["fieldPath"] == "metadata.name", variable
    # The daemon refuses a --miss-log-dir that does not exist: an init container makes it, on the
    # same volume, with the same variable.
    volume_of = {m["mountPath"]: m["name"] for m in container["volumeMounts"]}
    (mount_path,) = [path for path in volume_of if miss_dir.startswith(path + "/")]
    made = False
    for init in pod_spec(deployment).get("initContainers", []):
        init_env = {e["name"]: e for e in init.get("env", [])}
        init_mounts = {m["mountPath"]: m["name"] for m in init.get("volumeMounts", [])}
        argv = container_argv(init, [])
        if miss_dir in argv and "mkdir" in argv[0] and init_mounts.get(mount_path) == volume_of[mount_path]:
            made = all(init_env[v]["valueFrom"]["fieldRef"]["fieldPath"] == "metadata.name" for v in variables)
    assert made, f"no init container creates {miss_dir}"
    # Compose runs one daemon, systemd one per host: a fixed directory is right there.
    assert option_value(daemon_arguments("compose animspaced"), "--miss-log-dir")
    assert option_value(daemon_arguments("animspaced.service"), "--miss-log-dir")


# ---------------------------------------------------------------------------------------------
# Ports, probes, services, images.


def envoy_config_text():
    (configmap,) = [c for c in objects_of("ConfigMap") if "envoy.yaml" in c.get("data", {})]
    return configmap["data"]["envoy.yaml"]


def envoy_config():
    return yaml.safe_load(envoy_config_text())


def resolve_target_port(service_port, container):
    target = service_port.get("targetPort", service_port["port"])
    if isinstance(target, str):
        (port,) = [p["containerPort"] for p in container["ports"] if p.get("name") == target]
        return port
    assert target in [p["containerPort"] for p in container["ports"]]
    return target


def selects(selector, pod_labels):
    return bool(selector) and all(pod_labels.get(k) == v for k, v in selector.items())


def test_ports_and_probes_agree_with_the_daemon_flags():
    deployment = daemon_deployment()
    container = daemon_container(deployment)
    arguments = daemon_arguments("deployment.yaml")
    grpc_port = port_of(option_value(arguments, "--listen"))
    metrics_port = port_of(option_value(arguments, "--metrics-listen"))
    assert grpc_port == 50051 and metrics_port == 9464
    named = {p["name"]: p["containerPort"] for p in container["ports"]}
    assert named == {"grpc": grpc_port, "metrics": metrics_port}
    # Native gRPC probes (grpc.health.v1) on the gRPC port: startup while loading, then liveness
    # and readiness.
    for probe in ("startupProbe", "readinessProbe", "livenessProbe"):
        assert container[probe]["grpc"]["port"] == grpc_port, probe
        assert container[probe]["grpc"].get("service", "") == "", f"{probe}: the daemon reports health for ''"
    annotations = deployment["spec"]["template"]["metadata"]["annotations"]
    assert int(annotations["prometheus.io/port"]) == metrics_port
    # Every other way of running the daemon listens on the same ports.
    for prefix in ("Dockerfile", "compose animspaced", "animspaced.service"):
        other = daemon_arguments(prefix)
        assert port_of(option_value(other, "--listen")) == grpc_port, prefix
        assert port_of(option_value(other, "--metrics-listen")) == metrics_port, prefix
    exposed = {int(p) for keyword, rest in dockerfile_runtime() if keyword == "EXPOSE" for p in rest.split()}
    assert exposed == {grpc_port, metrics_port}
    published = {int(str(p).rsplit(":", 1)[1]) for p in compose()["services"]["animspaced"]["ports"]}
    assert published == {grpc_port, metrics_port}
    # Compose's jobs reach the daemon by its service name on the gRPC port.
    (where, loadtest), = invocations_in("compose loadtest", "animspace-loadtest")
    assert option_values(loadtest, "--server") == [f"animspaced:{grpc_port}"]


def test_headless_service_reaches_every_ready_replica_on_the_daemon_ports():
    deployment = daemon_deployment()
    container = daemon_container(deployment)
    pod_labels = deployment["spec"]["template"]["metadata"]["labels"]
    headless = [s for s in objects_of("Service") if s["spec"].get("clusterIP") == "None"]
    assert len(headless) == 1, "expected one headless Service (clusterIP: None)"
    service = headless[0]
    assert selects(service["spec"]["selector"], pod_labels)
    assert not service["spec"].get("publishNotReadyAddresses", False), "loading replicas must stay out of DNS"
    grpc_port = port_of(option_value(daemon_arguments("deployment.yaml"), "--listen"))
    ports = {p["name"]: p for p in service["spec"]["ports"]}
    # Clients dial the pod addresses from DNS directly, so the port they use must be the
    # container's own: port == targetPort == containerPort.
    assert ports["grpc"]["port"] == resolve_target_port(ports["grpc"], container) == grpc_port
    assert ports["grpc"].get("appProtocol") == "grpc"
    for port in ports.values():
        assert port["port"] == resolve_target_port(port, container)


def test_envoy_front_proxy_balances_over_the_headless_service():
    kustomization = yaml.safe_load((DEPLOY / "kubernetes" / "kustomization.yaml").read_text())
    (headless,) = [s for s in objects_of("Service") if s["spec"].get("clusterIP") == "None"]
    grpc_port = port_of(option_value(daemon_arguments("deployment.yaml"), "--listen"))
    config = envoy_config()
    (cluster,) = config["static_resources"]["clusters"]
    assert cluster["type"] == "STRICT_DNS", "Envoy must resolve every replica, not one virtual IP"
    (endpoints,) = cluster["load_assignment"]["endpoints"]
    (endpoint,) = endpoints["lb_endpoints"]
    address = endpoint["endpoint"]["address"]["socket_address"]
    assert address["address"] == f"{headless['metadata']['name']}.{kustomization['namespace']}.svc.cluster.local"
    assert address["port_value"] == grpc_port
    assert "http2_protocol_options" in str(cluster["typed_extension_protocol_options"])
    assert any("grpc_health_check" in check for check in cluster["health_checks"])
    (listener,) = config["static_resources"]["listeners"]
    listener_port = listener["address"]["socket_address"]["port_value"]
    # Long streams must not be cut by Envoy's default 15 s route timeout.
    (route,) = [r for vh in listener["filter_chains"][0]["filters"][0]["typed_config"]["route_config"]["virtual_hosts"]
                for r in vh["routes"]]
    assert route["route"]["cluster"] == cluster["name"] and route["route"]["timeout"] == "0s"
    envoy = workload("animspace-envoy")
    (envoy_container,) = pod_spec(envoy)["containers"]
    assert listener_port in [p["containerPort"] for p in envoy_container["ports"]]
    (service,) = [s for s in objects_of("Service") if s["metadata"]["name"] == "animspace-envoy"]
    assert service["spec"].get("type", "ClusterIP") == "ClusterIP" and service["spec"].get("clusterIP") != "None"
    assert selects(service["spec"]["selector"], envoy["spec"]["template"]["metadata"]["labels"])
    (port,) = service["spec"]["ports"]
    assert resolve_target_port(port, envoy_container) == listener_port
    assert port["port"] == grpc_port  # clients switch between Envoy and direct balancing by host name only
    config_volumes = [v for v in pod_spec(envoy)["volumes"] if "configMap" in v]
    assert [v["configMap"]["name"] for v in config_volumes] == [c["metadata"]["name"] for c in objects_of("ConfigMap")]


def test_one_image_everywhere():
    for file, obj in kubernetes_objects():
        if obj["kind"] in ("Deployment", "CronJob", "Job") and obj["metadata"]["name"] != "animspace-envoy":
            for container in pod_containers(obj):
                assert container["image"] == IMAGE, f"{file}: {container['name']}"
    images = {name: s.get("image") for name, s in compose()["services"].items()}
    assert set(images.values()) == {IMAGE}, images
    assert f"-t {IMAGE}" in (DEPLOY / "container" / "Dockerfile").read_text()
    assert daemon_container(daemon_deployment())["image"] == pod_spec(only("CronJob"))["containers"][0]["image"]


def test_container_image_stages():
    stages = [rest for keyword, rest in dockerfile() if keyword == "FROM"]
    assert stages[0].split()[0] == "debian:12" and stages[-1].split()[0] == "debian:12-slim"
    build_runs = " ".join(rest for keyword, rest in dockerfile()[:dockerfile().index(dockerfile_runtime()[0])]
                          if keyword == "RUN")
    assert "scripts/install-deps.sh" in build_runs
    presets = json.loads((ROOT / "CMakePresets.json").read_text())
    preset = re.search(r"cmake --preset (\S+)", build_runs).group(1)
    assert preset in [p["name"] for p in presets["configurePresets"]]
    targets = re.search(r"--target ((?:[\w-]+ ?)+)", build_runs).group(1).split()
    assert sorted(targets) == sorted(PROGRAMS)
    cmake_files = [p for pattern in ("CMakeLists.txt", "*/CMakeLists.txt", "*/*/CMakeLists.txt")
                   for p in ROOT.glob(pattern) if not p.relative_to(ROOT).parts[0].startswith("build")]
    cmake_text = " ".join(p.read_text() for p in cmake_files)
    for target in targets:
        assert re.search(rf"add_executable\({re.escape(target)}\s", cmake_text), target
    runtime = dockerfile_runtime()
    users = [rest for keyword, rest in runtime if keyword == "USER"]
    assert users and users[-1].split(":")[0] not in ("root", "0")
    copied = " ".join(rest for keyword, rest in runtime if keyword == "COPY")
    for program in PROGRAMS:
        assert re.search(rf"/{re.escape(program)}\b", copied), f"{program} is not copied into the image"
    assert image_entrypoint() == ["animspaced"]


def test_runtime_stage_installs_the_package_of_every_linked_library():
    ldd, dpkg = shutil.which("ldd"), shutil.which("dpkg-query")
    if ldd is None or dpkg is None:
        pytest.skip("ldd or dpkg-query is not available")
    runtime_runs = " ".join(rest for keyword, rest in dockerfile_runtime() if keyword == "RUN")
    installed = set(re.findall(r"\b(lib[\w.+-]+|zlib1g|ca-certificates)\b", runtime_runs))
    # Mesa's EGL and llvmpipe are loaded at run time (libglvnd vendor files), not linked.
    assert {"libegl1", "libgles2", "libegl-mesa0", "libgl1-mesa-dri"} <= installed
    libraries = set()
    for program in PROGRAMS:
        out = subprocess.run([ldd, str(binary(program))], capture_output=True, text=True, timeout=30).stdout
        libraries |= {os.path.realpath(m) for m in re.findall(r"=> (/\S+)", out)}
    if any(re.search(r"/lib[at]san\.so", library) for library in libraries):
        pytest.skip("this build is sanitized (make check-asan); the image ships the release build")
    result = subprocess.run([dpkg, "-S", *sorted(libraries)], capture_output=True, text=True, timeout=30)
    packages = {line.split(":")[0] for line in result.stdout.splitlines() if ": " in line}
    if not packages:
        pytest.skip("the linked libraries do not come from Debian packages here")
    # In debian:12-slim already: the C and C++ runtime.
    base = {"libc6", "libgcc-s1", "libstdc++6"}
    assert packages - base <= installed, f"missing from the runtime stage: {sorted(packages - base - installed)}"


# ---------------------------------------------------------------------------------------------
# Scaling and shutdown.


def test_autoscaler_and_disruption_budget_target_the_daemon():
    deployment = daemon_deployment()
    hpa, pdb = only("HorizontalPodAutoscaler"), only("PodDisruptionBudget")
    target = hpa["spec"]["scaleTargetRef"]
    assert (target["apiVersion"], target["kind"], target["name"]) == ("apps/v1", "Deployment",
                                                                      deployment["metadata"]["name"])
    assert 1 <= hpa["spec"]["minReplicas"] <= hpa["spec"]["maxReplicas"]
    (metric,) = hpa["spec"]["metrics"]
    assert metric["resource"]["name"] == "cpu" and metric["resource"]["target"]["type"] == "Utilization"
    # Utilization is relative to the request: without one the HPA cannot compute it.
    container = daemon_container(deployment)
    assert container["resources"]["requests"]["cpu"]
    # A drain can always evict one replica at the minimum size.
    assert pdb["spec"]["minAvailable"] < hpa["spec"]["minReplicas"]
    assert selects(pdb["spec"]["selector"]["matchLabels"], deployment["spec"]["template"]["metadata"]["labels"])
    # The evaluation pool is sized to the CPU limit (the default counts the node's cores).
    work_threads = int(option_value(daemon_arguments("deployment.yaml"), "--work-threads"))
    assert work_threads == int(container["resources"]["limits"]["cpu"])


def test_shutdown_grace_fits_inside_every_supervisor_timeout():
    def grace_s(arguments):
        values = option_values(arguments, "--shutdown-grace-ms")
        return int(values[0]) / 1000 if values else 5.0  # the daemon's default

    deployment = daemon_deployment()
    container = daemon_container(deployment)
    pre_stop = container["lifecycle"]["preStop"]["exec"]["command"]
    assert pathlib.PurePosixPath(pre_stop[0]).name == "sleep"
    budget = float(pre_stop[1]) + grace_s(daemon_arguments("deployment.yaml"))
    assert pod_spec(deployment)["terminationGracePeriodSeconds"] > budget
    service = compose()["services"]["animspaced"]
    assert int(service["stop_grace_period"].rstrip("s")) > grace_s(daemon_arguments("compose animspaced"))
    assert service.get("stop_signal", "SIGTERM") == "SIGTERM"
    unit = systemd_unit("animspaced.service")
    assert float(unit_values(unit, "Service", "TimeoutStopSec")[0]) > grace_s(daemon_arguments("animspaced.service"))


def test_systemd_units_confine_writes_to_what_each_program_writes():
    daemon_unit = systemd_unit("animspaced.service")
    daemon = daemon_arguments("animspaced.service")
    assert option_value(daemon, "--model-repository") in unit_values(daemon_unit, "Service", "ReadOnlyPaths")
    assert option_value(daemon, "--miss-log-dir") in unit_values(daemon_unit, "Service", "ReadWritePaths")
    assert unit_values(daemon_unit, "Service", "ProtectSystem") == ["strict"]
    # Mesa's llvmpipe JIT needs memory that becomes executable: W^X would crash the first
    # thumbnail, unless thumbnails are off.
    if option_values(daemon, "--renderer") != ["none"]:
        assert unit_values(daemon_unit, "Service", "MemoryDenyWriteExecute") in ([], ["no"])
    retrain_unit = systemd_unit("animspace-retrain.service")
    (where, retrain), = invocations_in("animspace-retrain.service", "animspace", "retrain-offline")
    assert option_value(retrain, "--repository") == option_value(daemon, "--model-repository")
    assert option_value(retrain, "--miss-logs") == option_value(daemon, "--miss-log-dir")
    assert option_value(retrain, "--repository") in unit_values(retrain_unit, "Service", "ReadWritePaths")
    assert option_value(retrain, "--miss-logs") in unit_values(retrain_unit, "Service", "ReadOnlyPaths")
    timer = systemd_unit("animspace-retrain.timer")
    assert unit_values(timer, "Timer", "Unit") in ([], ["animspace-retrain.service"])
    assert unit_values(timer, "Timer", "OnCalendar")


def test_compose_volumes_mirror_the_kubernetes_modes():
    services = compose()["services"]

    def mounts(name):
        result = {}
        for volume in services[name].get("volumes", []):
            source, target, *mode = volume.split(":")
            result[target] = (source, mode == ["ro"])
        return result

    daemon = daemon_arguments("compose animspaced")
    (where, retrain), = invocations_in("compose retrain", "animspace", "retrain-offline")
    models = mounts("animspaced")[option_value(daemon, "--model-repository")]
    misses = mounts("animspaced")[option_value(daemon, "--miss-log-dir")]
    assert models[1] is True and misses[1] is False
    assert mounts("retrain")[option_value(retrain, "--repository")] == (models[0], False)
    assert mounts("retrain")[option_value(retrain, "--miss-logs")] == (misses[0], True)
    (where, seed), = invocations_in("compose seed-models", "animspace", "demo-repository")
    assert mounts("seed-models")[seed[-1]] == (models[0], False)
    assert set(compose()["volumes"]) >= {models[0], misses[0]}
