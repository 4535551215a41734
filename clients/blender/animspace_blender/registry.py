"""Registering a module's Blender classes: in order, and unregistering them in reverse."""
from typing import Callable, Sequence, Tuple

import bpy


def register_classes(classes: Sequence[type]) -> None:
    for cls in classes:
        bpy.utils.register_class(cls)


def unregister_classes(classes: Sequence[type]) -> None:
    for cls in reversed(classes):
        bpy.utils.unregister_class(cls)


def for_classes(classes: Sequence[type]) -> Tuple[Callable[[], None], Callable[[], None]]:
    """A module's ``register`` and ``unregister`` when it has nothing to do beyond its classes."""
    return (lambda: register_classes(classes)), (lambda: unregister_classes(classes))
