"""Writing output files safely: atomically, and never over a user's file unless asked."""

import os
import secrets
from pathlib import Path

__all__ = ["write_atomic"]


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
    """
    path = Path(path)
    if isinstance(data, str):
        data = data.encode("utf-8")
    if not overwrite and path.exists():
        raise FileExistsError(f"{path} already exists (pass overwrite to replace it)")
    folder = path.parent if str(path.parent) else Path(".")
    if not folder.is_dir():
        raise FileNotFoundError(f"folder {folder} does not exist")
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
                raise FileExistsError(f"{path} already exists (pass overwrite to replace it)") from None
            except OSError:  # file systems without hard links
                if path.exists():
                    raise FileExistsError(f"{path} already exists (pass overwrite to replace it)") from None
                os.replace(tmp_name, path)
    finally:
        if os.path.exists(tmp_name):
            os.unlink(tmp_name)
    return path
