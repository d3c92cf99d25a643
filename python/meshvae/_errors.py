"""The exceptions of meshvae: every error of the Rust crates arrives as one of these, carrying
the crates' message (which names the file or argument and what is wrong)."""


class MeshvaeError(Exception):
    """Base class of every error raised by meshvae."""


class InputError(MeshvaeError, ValueError):
    """Bad input: an array of the wrong shape or dtype, faces that do not fit the vertices, a
    mesh the operation cannot handle, an unknown option, or a file whose contents are invalid."""


class FileError(MeshvaeError, OSError):
    """A file or folder that cannot be read or written (missing, unreadable, no permission)."""


# Shown as meshvae.InputError etc. in tracebacks, where users import them from.
for _cls in (MeshvaeError, InputError, FileError):
    _cls.__module__ = "meshvae"
del _cls
