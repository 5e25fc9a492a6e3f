"""atomic_write.py: write_atomic(path, text), shared by the pipeline scripts.

Writes beside the target (a temporary file in the same folder) and renames it over the target, so
make never sees a half-written file; the temporary file is removed on any failure.
"""
import os
import tempfile


def write_atomic(path, text):
    d = os.path.dirname(os.path.abspath(path))
    fd, tmp = tempfile.mkstemp(prefix="." + os.path.basename(path) + ".", dir=d)
    try:
        with os.fdopen(fd, "w") as f:
            f.write(text)
        os.chmod(tmp, 0o644)
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise
