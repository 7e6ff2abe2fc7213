"""Cache folders of numba and matplotlib that a user can always write.

Both keep their caches under the home folder. With a home folder the user cannot write (a
service account, a read-only container) numba raises when the first kernel is decorated, so
every command, even ``npmrf3d info``, ended in a traceback, and matplotlib printed two warning
lines ahead of every message. Such a user gets a private folder in the temporary folder
instead (owned by the user and writable by no one else: a shared folder must not hold compiled
code or settings that another user could have put there).

Importing this module settles matplotlib's folder (:func:`settle_matplotlib_config`), so the
package imports it before any module that imports matplotlib; numba's folder is chosen in
:mod:`npmrf3d._kernels._jit`.
"""

from __future__ import annotations

import os
import tempfile


def writable_folder(path: str, *, private: bool = False) -> bool:
    """Whether a file can be made in ``path`` (created if missing). ``private``: the folder must
    also be owned by this user and writable by no one else."""
    try:
        os.makedirs(path, mode=0o700, exist_ok=True)
        if private and hasattr(os, "getuid"):
            info = os.stat(path)
            if info.st_uid != os.getuid() or info.st_mode & 0o022:
                return False
        tempfile.TemporaryFile(dir=path).close()
    except OSError:
        return False
    return True


def private_temp_folder(name: str) -> str | None:
    """``<temporary folder>/npmrf3d-<name>-<user id>`` if it is (or can be made) a private
    writable folder of this user, else None."""
    user = os.getuid() if hasattr(os, "getuid") else "user"
    path = os.path.join(tempfile.gettempdir(), f"npmrf3d-{name}-{user}")
    return path if writable_folder(path, private=True) else None


def settle_matplotlib_config() -> None:
    """Point ``MPLCONFIGDIR`` at a private temporary folder when it is unset and matplotlib's
    default (``$XDG_CONFIG_HOME/matplotlib`` or ``~/.config/matplotlib``) cannot be written;
    call before matplotlib is imported."""
    if os.environ.get("MPLCONFIGDIR"):
        return
    base = os.environ.get("XDG_CONFIG_HOME") or os.path.join(os.path.expanduser("~"), ".config")
    if writable_folder(os.path.join(base, "matplotlib")):
        return
    folder = private_temp_folder("matplotlib")
    if folder is not None:
        os.environ["MPLCONFIGDIR"] = folder


settle_matplotlib_config()
