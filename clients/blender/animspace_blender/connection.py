"""The connection: an ``animspace.Client`` made from the scene's settings, kept while they do not
change (a frame-change handler calls every frame), and the one place errors become reports.

Every failure an operator can meet — an RPC the server refused (its message names the field or
the model), a server that cannot be reached, a file that cannot be read, bad input the client
refuses before sending — is shown as a Blender report (``{'ERROR'}``, the server's message in it)
and cancels the operator; none escapes as a traceback. Handlers cannot report: they keep the
message in ``scene.animspace.last_error`` for the panel and print it.
"""
from typing import Callable, Dict, List, Optional, Tuple

import bpy

import animspace

from . import registry

_clients: Dict[Tuple, animspace.Client] = {}
# Called when the clients close: what was cached from a server (key points) is asked again.
reset_hooks: List[Callable[[], None]] = []

# What an operator turns into a report rather than a traceback: the client's own errors (RPC
# failures with the server's message, protocol errors), bad arguments it refused before sending
# (ValueError, TypeError) and files (OSError).
EXPECTED_ERRORS = (animspace.Error, ValueError, TypeError, OSError)


class SetupError(Exception):
    """Something the user must fix in Blender (no source object, wrong object type, …)."""


def file_path(path: str, what: str) -> str:
    """An absolute path for a property's file path ("//…" is relative to the saved .blend)."""
    if path.startswith("//") and not bpy.data.filepath:
        raise SetupError(f"{what}: '{path}' is relative to the .blend file, which is not saved yet; save it or "
                         "give an absolute path")
    return bpy.path.abspath(path)


def _read(path: str, what: str, mode: str = "rb"):
    full = file_path(path, what)
    try:
        with open(full, mode) as f:
            return f.read()
    except OSError as error:
        raise SetupError(f"{what}: cannot read {full}: {error.strerror or error}") from error


def _settings_key(settings) -> Tuple:
    return (settings.address, settings.token_file, settings.use_tls, settings.root_certificates_file,
            settings.client_certificate_file, settings.client_key_file, settings.server_name,
            round(settings.deadline_s, 6))


def client(context) -> animspace.Client:
    """The client for ``context.scene.animspace``'s connection settings (made on first use)."""
    settings = context.scene.animspace
    key = _settings_key(settings)
    existing = _clients.get(key)
    if existing is not None and not existing.closed:
        return existing
    if not settings.address.strip():
        raise SetupError("Server: give the daemon's address, host:port")
    token: Optional[str] = None
    if settings.token_file:
        token = _read(settings.token_file, "Token file", "r").strip()
    tls = {}
    if settings.use_tls:  # only then: the panel hides the TLS files while it is off
        tls["tls"] = True
        if settings.root_certificates_file:
            tls["root_certificates"] = _read(settings.root_certificates_file, "CA")
        if settings.client_certificate_file or settings.client_key_file:
            tls["client_certificate"] = _read(settings.client_certificate_file, "Client certificate")
            tls["client_key"] = _read(settings.client_key_file, "Client key")
        if settings.server_name:
            tls["server_name"] = settings.server_name
    made = animspace.Client(settings.address.strip(), token=token, deadline_s=settings.deadline_s, **tls)
    close_clients()  # settings changed: the old channel is of no further use
    _clients[key] = made
    return made


def close_clients() -> None:
    for made in _clients.values():
        made.close()
    _clients.clear()
    for hook in reset_hooks:
        hook()


def error_text(error: BaseException) -> str:
    """One line for a report: an RPC error reads "<rpc> failed: <CODE>: <server's message>"."""
    return str(error) or type(error).__name__


def in_handler(scene, workflow: str, action: Callable[[], object], prefix: str = "",
               on_error: Optional[Callable[[], None]] = None) -> None:
    """Runs ``action`` for a frame-change handler, which cannot report: success clears
    ``last_error``; an expected failure calls ``on_error``, is kept there (after ``prefix``) for the
    panel and printed."""
    settings = scene.animspace
    try:
        action()
        settings.last_error = ""
    except (SetupError,) + EXPECTED_ERRORS as error:
        if on_error is not None:
            on_error()
        settings.last_error = prefix + error_text(error)
        print(f"animspace {workflow}, frame {scene.frame_current}: {settings.last_error}")


class ReportingOperator:
    """An operator's ``execute`` (mixed in before ``bpy.types.Operator``): ``run(context)`` does the
    work and returns its INFO report, or None for none; expected failures become an ERROR report
    and CANCELLED."""
    bl_options = {"REGISTER", "UNDO"}

    def run(self, context) -> Optional[str]:
        raise NotImplementedError

    def execute(self, context):
        try:
            message = self.run(context)
        except (SetupError,) + EXPECTED_ERRORS as error:
            self.report({"ERROR"}, error_text(error))
            return {"CANCELLED"}
        if message:
            self.report({"INFO"}, message)
        return {"FINISHED"}


def chosen_model(context, kind: str = "a model", prop: str = "model", label: str = "Model") -> str:
    """The model named by the scene setting ``prop``; a SetupError asking for ``kind`` when empty."""
    model = getattr(context.scene.animspace, prop).strip()
    if not model:
        raise SetupError(f"{label}: choose {kind} (Connect lists them)")
    return model


class ANIMSPACE_OT_connect(ReportingOperator, bpy.types.Operator):
    """Check the server's health and list its models"""
    bl_idname = "animspace.connect"
    bl_label = "Connect"
    bl_options = {"REGISTER"}

    def run(self, context):
        settings = context.scene.animspace
        settings.health = "not checked"
        settings.models.clear()
        close_clients()  # Connect starts afresh: a new channel, nothing cached from before
        made = client(context)
        settings.health = made.health()
        for summary in made.list_models():
            version = summary.default
            item = settings.models.add()
            item.name = summary.name
            if version is None:  # every version failed to load
                item.kind = "FAILED"
                continue
            item.kind = version.kind
            item.version = version.version
            item.point_count = version.point_count
            item.key_point_count = version.key_point_count
            item.bone_count = version.bone_count
            item.lod_level_count = version.lod_level_count
            item.server_engine = version.server_engine
            item.has_tangents = "animspace.tangents" in version.sections
        return f"{settings.address}: {settings.health}, {len(settings.models)} models"


def find_model(context, name: str):
    """The listed model called ``name``, or None when the list has not been fetched or lacks it."""
    return context.scene.animspace.models.get(name)


_CLASSES = (ANIMSPACE_OT_connect,)

register, unregister = registry.for_classes(_CLASSES)
