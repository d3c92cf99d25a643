//! numpy arrays in and out. Inputs are checked here, each error naming the argument, so that
//! nothing malformed reaches the crates; outputs are handed to numpy without a copy (a `Vec`
//! becomes the array's buffer).

use crate::errors::input;
use mesh_io::{Face, Point};
use numpy::{
    Element, PyArray1, PyArrayDyn, PyArrayMethods, PyReadonlyArrayDyn, PyUntypedArray,
    PyUntypedArrayMethods,
};
use pyo3::prelude::*;

/// `obj` as a numpy array (`numpy.asarray`, so lists are accepted too).
fn ndarray<'py>(obj: &Bound<'py, PyAny>, name: &str) -> PyResult<Bound<'py, PyUntypedArray>> {
    if let Ok(a) = obj.cast::<PyUntypedArray>() {
        return Ok(a.clone());
    }
    let py = obj.py();
    let converted = py
        .import("numpy")?
        .call_method1("asarray", (obj,))
        .map_err(|e| input(format!("{name}: not convertible to an array ({e})")))?;
    converted
        .cast_into::<PyUntypedArray>()
        .map_err(|_| input(format!("{name}: not convertible to an array")))
}

fn dtype_name(a: &Bound<'_, PyUntypedArray>) -> String {
    a.dtype().to_string()
}

/// The values of `a` in C order (a copy that also makes a strided view contiguous).
fn values<T: Element + Copy>(a: &PyReadonlyArrayDyn<'_, T>) -> Vec<T> {
    match a.as_slice() {
        Ok(s) => s.to_vec(),
        Err(_) => a.as_array().iter().copied().collect(),
    }
}

/// A float32 or float64 array as f32 values in C order, with its shape.
pub fn floats(obj: &Bound<'_, PyAny>, name: &str) -> PyResult<(Vec<f32>, Vec<usize>)> {
    float_values(obj, name, |v| v, |v| v as f32)
}

/// A float32 or float64 array as f64 values in C order (float32 widened exactly), with its
/// shape.
pub fn floats64(obj: &Bound<'_, PyAny>, name: &str) -> PyResult<(Vec<f64>, Vec<usize>)> {
    float_values(obj, name, f64::from, |v| v)
}

/// A float32 or float64 array's values in C order, each converted by `from32` or `from64`.
fn float_values<T>(
    obj: &Bound<'_, PyAny>,
    name: &str,
    from32: impl Fn(f32) -> T,
    from64: impl Fn(f64) -> T,
) -> PyResult<(Vec<T>, Vec<usize>)> {
    let a = ndarray(obj, name)?;
    let shape = a.shape().to_vec();
    if let Ok(x) = a.extract::<PyReadonlyArrayDyn<'_, f32>>() {
        return Ok((values(&x).into_iter().map(from32).collect(), shape));
    }
    if let Ok(x) = a.extract::<PyReadonlyArrayDyn<'_, f64>>() {
        return Ok((values(&x).into_iter().map(from64).collect(), shape));
    }
    Err(input(format!(
        "{name}: expected a float32 or float64 array, got dtype {}",
        dtype_name(&a)
    )))
}

/// An integer array as u32 values in C order, with its shape; negative or too large values are
/// errors naming the argument.
pub fn indices(obj: &Bound<'_, PyAny>, name: &str) -> PyResult<(Vec<u32>, Vec<usize>)> {
    fn convert<T: Element + Copy + TryInto<u32> + std::fmt::Display>(
        a: &Bound<'_, PyUntypedArray>,
        name: &str,
    ) -> Option<PyResult<Vec<u32>>> {
        let x = a.extract::<PyReadonlyArrayDyn<'_, T>>().ok()?;
        Some(
            values(&x)
                .into_iter()
                .map(|v| {
                    v.try_into()
                        .map_err(|_| input(format!("{name}: index {v} is not in 0..2^32")))
                })
                .collect(),
        )
    }
    let a = ndarray(obj, name)?;
    let shape = a.shape().to_vec();
    let converted = convert::<i32>(&a, name)
        .or_else(|| convert::<i64>(&a, name))
        .or_else(|| convert::<u32>(&a, name))
        .or_else(|| convert::<u64>(&a, name));
    match converted {
        Some(v) => Ok((v?, shape)),
        None => Err(input(format!(
            "{name}: expected an integer array, got dtype {}",
            dtype_name(&a)
        ))),
    }
}

/// Checks `shape` against `expected` (`None`: any size), describing the layout as `layout`.
pub fn check_shape(
    name: &str,
    shape: &[usize],
    expected: &[Option<usize>],
    layout: &str,
) -> PyResult<()> {
    let fits = shape.len() == expected.len()
        && shape
            .iter()
            .zip(expected)
            .all(|(s, e)| e.is_none_or(|e| e == *s));
    if fits {
        Ok(())
    } else {
        Err(input(format!(
            "{name}: expected an array of shape {layout}, got shape {shape:?}"
        )))
    }
}

/// `[V, 3]` positions.
pub fn points(obj: &Bound<'_, PyAny>, name: &str) -> PyResult<Vec<Point>> {
    let (v, shape) = floats(obj, name)?;
    check_shape(name, &shape, &[None, Some(3)], "[V, 3]")?;
    Ok(v.chunks_exact(3).map(|p| [p[0], p[1], p[2]]).collect())
}

/// `[N, V, 3]` frames, flat and frame-major, with (N, V).
pub fn frames(obj: &Bound<'_, PyAny>, name: &str) -> PyResult<(Vec<Point>, usize, usize)> {
    let (v, shape) = floats(obj, name)?;
    check_shape(name, &shape, &[None, None, Some(3)], "[N, V, 3]")?;
    let points = v.chunks_exact(3).map(|p| [p[0], p[1], p[2]]).collect();
    Ok((points, shape[0], shape[1]))
}

/// `[F, 3]` triangles whose indices are below `vertex_count` (the rows of `vertices_name`).
pub fn faces(
    obj: &Bound<'_, PyAny>,
    name: &str,
    vertex_count: usize,
    vertices_name: &str,
) -> PyResult<Vec<Face>> {
    let (v, shape) = indices(obj, name)?;
    check_shape(name, &shape, &[None, Some(3)], "[F, 3]")?;
    if let Some((i, &bad)) = v
        .iter()
        .enumerate()
        .find(|(_, x)| **x as usize >= vertex_count)
    {
        return Err(input(format!(
            "{name}: row {} refers to vertex {bad}, but {vertices_name} has {vertex_count} vertices",
            i / 3
        )));
    }
    Ok(v.chunks_exact(3).map(|f| [f[0], f[1], f[2]]).collect())
}

/// `data` as a numpy array of `shape` (its buffer, not a copy).
pub fn array<'py, T: Element>(
    py: Python<'py>,
    data: Vec<T>,
    shape: &[usize],
) -> PyResult<Bound<'py, PyArrayDyn<T>>> {
    PyArray1::from_vec(py, data).reshape(shape.to_vec())
}

/// Positions as float32 `[V, 3]`.
pub fn points_out<'py>(py: Python<'py>, p: Vec<Point>) -> PyResult<Bound<'py, PyArrayDyn<f32>>> {
    let n = p.len();
    array(py, p.into_flattened(), &[n, 3])
}

/// Faces as int32 `[F, 3]` (vertex counts stay far below 2^31).
pub fn faces_out<'py>(py: Python<'py>, f: &[Face]) -> PyResult<Bound<'py, PyArrayDyn<i32>>> {
    let data = f
        .as_flattened()
        .iter()
        .map(|&i| i32::try_from(i).map_err(|_| input(format!("vertex index {i} exceeds int32"))))
        .collect::<PyResult<Vec<i32>>>()?;
    array(py, data, &[f.len(), 3])
}

/// Marks `a` read-only: for arrays that mirror state held on the Rust side.
pub fn read_only<T: Element>(a: &Bound<'_, PyArrayDyn<T>>) -> PyResult<()> {
    a.getattr("flags")?.setattr("writeable", false)
}
