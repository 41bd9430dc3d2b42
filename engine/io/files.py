"""Writing output files safely: atomically, and never over a user's file unless asked."""

import os
import secrets
from pathlib import Path

import cv2

from ..errors import InputError, OutputError

__all__ = ["write_atomic", "write_image", "check_writable", "check_output_file"]


def check_writable(folder, *, created=False):
    """Check that files can be created in ``folder`` (a probe file is made and removed), so
    a long run does not fail only when it writes its result.

    Parameters
    ----------
    folder : str or os.PathLike
    created : bool, optional
        ``folder`` is made by the writer if missing: its nearest existing parent is probed.

    Raises
    ------
    OutputError
        ``folder`` is missing (and not ``created``), not a folder, or may not be written in.
    """
    folder = Path(folder).resolve()
    while created and not folder.exists() and folder != folder.parent:
        folder = folder.parent
    if not folder.is_dir():
        raise OutputError(f"{folder} is not a folder")
    probe = folder / f".cable_recon-probe-{secrets.token_hex(6)}"
    try:
        os.close(os.open(probe, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600))
    except OSError as error:
        raise OutputError(f"cannot write in {folder}: {error.strerror or error}") from None
    os.unlink(probe)


def check_output_file(path, *, overwrite=False):
    """Check, before the work, that ``path`` can be written as a new file (or replaced, with
    ``overwrite``).

    Raises
    ------
    OutputError
        ``path`` is a folder, or its folder is missing or may not be written in.
    InputError
        ``path`` exists and ``overwrite`` is off.
    """
    path = Path(path)
    if path.is_dir():
        raise OutputError(f"{path} is a folder, not a file")
    if path.exists() and not overwrite:
        raise InputError(f"{path} exists (use --overwrite to replace it)")
    check_writable(path.resolve().parent)


def write_atomic(path, data, *, overwrite=False):
    """Write ``data`` to ``path`` so that readers see either nothing or the whole file.

    The data goes to a temporary file in the same folder first, which is then moved into place.

    Parameters
    ----------
    path : str or os.PathLike
        Destination file. Its folder must exist.
    data : str or bytes
        Contents; ``str`` is written as UTF-8.
    overwrite : bool, optional
        Replace an existing file. Without it an existing file is left untouched and
        :class:`FileExistsError` is raised (also when the file appears while writing).

    Returns
    -------
    pathlib.Path
        The path written.

    Raises
    ------
    FileExistsError
        ``path`` exists and ``overwrite`` is false.
    FileNotFoundError
        The destination folder does not exist.
    OutputError
        The file cannot be written (a folder one may not write in, a full disk); nothing is
        left behind.
    """
    path = Path(path)
    if isinstance(data, str):
        data = data.encode("utf-8")
    if not overwrite and path.exists():
        raise FileExistsError(f"{path} already exists (pass overwrite to replace it)")
    folder = path.parent if str(path.parent) else Path(".")
    if not folder.is_dir():
        raise FileNotFoundError(f"folder {folder} does not exist")
    try:
        _write_through_temporary(path, folder, data, overwrite)
    except FileExistsError:
        raise
    except OSError as error:
        raise OutputError(f"cannot write {path}: {error.strerror or error}") from None
    return path


def _write_through_temporary(path, folder, data, overwrite):
    """``data`` into a new file in ``folder``, then moved to ``path`` (the temporary file is
    removed whatever happens)."""
    # os.open with mode 0o666 lets the umask decide the permissions, as for any new file
    # (tempfile.mkstemp would leave the output readable by its owner only).
    while True:
        tmp_name = str(folder / f".{path.name}.{secrets.token_hex(6)}.tmp")
        try:
            fd = os.open(tmp_name, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666)
            break
        except FileExistsError:
            continue
    if overwrite and path.exists():
        os.chmod(tmp_name, path.stat().st_mode & 0o7777)
    try:
        with os.fdopen(fd, "wb") as handle:
            handle.write(data)
            handle.flush()
            os.fsync(handle.fileno())
        if overwrite:
            os.replace(tmp_name, path)
        else:
            # A hard link fails if the name was taken meanwhile: no clobbering even in a race.
            try:
                os.link(tmp_name, path)
            except FileExistsError:
                raise FileExistsError(f"{path} already exists "
                                      "(pass overwrite to replace it)") from None
            except OSError:  # file systems without hard links
                if path.exists():
                    raise FileExistsError(f"{path} already exists "
                                          "(pass overwrite to replace it)") from None
                os.replace(tmp_name, path)
    finally:
        if os.path.exists(tmp_name):
            os.unlink(tmp_name)


def write_image(path, image, *, overwrite=False):
    """Write an image file (its format from the suffix) as :func:`write_atomic` does.

    ``cv2.imwrite`` only returns False when it cannot write; this raises.

    Parameters
    ----------
    path : str or os.PathLike
    image : ndarray
        As ``cv2.imwrite`` takes it (BGR, or one channel).
    overwrite : bool, optional

    Returns
    -------
    pathlib.Path
    """
    path = Path(path)
    ok, data = cv2.imencode(path.suffix, image)
    if not ok:
        raise ValueError(f"cannot encode an image as {path.suffix!r}")
    return write_atomic(path, data.tobytes(), overwrite=overwrite)
