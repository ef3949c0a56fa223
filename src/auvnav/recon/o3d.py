"""Open3D, loaded lazily (it takes seconds) and with the libusb its Linux wheel links against.

Open3D's wheel for Linux needs ``libusb-1.0.so.0`` (for its RealSense support), which a fresh machine
may not have; the ``libusb-package`` dependency ships the library, and :func:`open3d` loads it into
the process's global symbol table before the first ``import open3d`` when the system has none.
Everything in auvnav imports Open3D through this function.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import sys
from types import ModuleType

from auvnav.errors import AuvnavError


def open3d() -> ModuleType:
    """The ``open3d`` module, imported on first use (libusb preloaded when the system lacks it)."""
    if "open3d" in sys.modules:
        return sys.modules["open3d"]
    if sys.platform.startswith("linux") and ctypes.util.find_library("usb-1.0") is None:
        try:
            import libusb_package

            path = libusb_package.get_library_path()
            if path is not None:
                ctypes.CDLL(str(path), mode=ctypes.RTLD_GLOBAL)
        except (ImportError, OSError):
            pass  # the import below says what is missing
    try:
        import open3d
    except (ImportError, OSError) as err:
        raise AuvnavError(
            f"reconstruction needs Open3D, which did not load ({err}); pip install open3d libusb-package"
        ) from None
    return open3d
