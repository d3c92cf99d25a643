//! Rust errors → Python exceptions, and load warnings → Python warnings.
//!
//! The exception classes live in `meshvae/_errors.py` because a class deriving from two built-in
//! exceptions (`MeshvaeError` and `ValueError`/`OSError`) is one line of Python and cannot be
//! declared with pyo3's `create_exception!` (one base only).

use pyo3::exceptions::PyUserWarning;
use pyo3::prelude::*;
use std::error::Error;
use std::ffi::CString;

/// Which Python exception an error becomes.
#[derive(Clone, Copy)]
pub enum Kind {
    /// `meshvae.InputError` (a `ValueError`): bad arrays, arguments, meshes or file contents.
    Input,
    /// `meshvae.FileError` (an `OSError`): a file that cannot be read or written.
    File,
}

/// The exception of `kind` carrying `message`.
pub fn raise(kind: Kind, message: impl Into<String>) -> PyErr {
    let name = match kind {
        Kind::Input => "InputError",
        Kind::File => "FileError",
    };
    let message = message.into();
    Python::attach(|py| {
        let made = py
            .import("meshvae._errors")
            .and_then(|m| m.getattr(name))
            .and_then(|class| class.call1((message,)));
        match made {
            Ok(exception) => PyErr::from_value(exception),
            Err(e) => e,
        }
    })
}

/// `InputError` with `message`.
pub fn input(message: impl Into<String>) -> PyErr {
    raise(Kind::Input, message)
}

/// Any error of the crates, with its message: a `FileError` when an I/O error is among its
/// causes (missing file, permission denied, …), an `InputError` otherwise.
pub fn to_py<E: Error + 'static>(err: E) -> PyErr {
    let mut cause: Option<&(dyn Error + 'static)> = Some(&err);
    while let Some(e) = cause {
        if e.is::<std::io::Error>() {
            return raise(Kind::File, err.to_string());
        }
        cause = e.source();
    }
    raise(Kind::Input, err.to_string())
}

/// Issues each message as a Python `UserWarning` (what the command line prints as `warning: …`).
pub fn warn_all<T: ToString>(py: Python<'_>, warnings: &[T]) -> PyResult<()> {
    let category = py.get_type::<PyUserWarning>();
    for w in warnings {
        // A NUL inside a message (never expected) is dropped rather than failing the call.
        let text = CString::new(w.to_string().replace('\0', "")).unwrap_or_default();
        PyErr::warn(py, &category, &text, 1)?;
    }
    Ok(())
}
