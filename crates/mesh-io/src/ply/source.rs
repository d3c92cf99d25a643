//! Reading PLY property values from the data section: whitespace-separated tokens (ASCII, with
//! line numbers for errors) or packed little/big-endian scalars (binary, with byte offsets).

use super::header::Scalar;
use crate::error::{MeshIoError, Result};
use crate::off::{lossy, parse_i64};
use std::path::Path;

/// A stream of property values, whatever the encoding.
pub(super) trait Source {
    /// A scalar of any type, as `f64` (exact for every PLY type).
    fn real(&mut self, ty: Scalar) -> Result<f64>;
    /// A scalar of an integer type.
    fn integer(&mut self, ty: Scalar) -> Result<i64>;
    /// Skips `n` scalars of type `ty`.
    fn skip(&mut self, ty: Scalar, n: usize) -> Result<()>;
    /// Line of the last value read; 0 in binary data.
    fn line(&self) -> usize;
    /// A parse error at the current position.
    fn error(&self, message: String) -> MeshIoError;
    /// The error for vertex `vertex` having the non-finite coordinate `value`.
    fn non_finite(&self, vertex: usize, value: f32) -> MeshIoError;
    /// Bytes not yet read: an upper bound on how much data is left, to cap reservations.
    fn remaining(&self) -> usize;
    /// What is left after the last element, when it is more than whitespace.
    fn trailing(&self) -> Option<String>;
}

/// ASCII data: one token per scalar, any whitespace between them.
pub(super) struct Ascii<'a> {
    bytes: &'a [u8],
    pos: usize,
    /// Line of `pos`.
    pos_line: usize,
    /// Line of the last token returned.
    token_line: usize,
    path: &'a Path,
}

impl<'a> Ascii<'a> {
    /// Data starting at byte `start`, which is on line `line`.
    pub(super) fn new(bytes: &'a [u8], start: usize, line: usize, path: &'a Path) -> Self {
        Self {
            bytes,
            pos: start.min(bytes.len()),
            pos_line: line,
            token_line: line,
            path,
        }
    }

    fn skip_whitespace(&mut self) {
        while let Some(&b) = self.bytes.get(self.pos) {
            if b == b'\n' {
                self.pos_line += 1;
            } else if !b.is_ascii_whitespace() {
                break;
            }
            self.pos += 1;
        }
    }

    fn token(&mut self) -> Result<&'a [u8]> {
        self.skip_whitespace();
        let start = self.pos;
        while self
            .bytes
            .get(self.pos)
            .is_some_and(|b| !b.is_ascii_whitespace())
        {
            self.pos += 1;
        }
        self.token_line = self.pos_line;
        if start == self.pos {
            return Err(self.error("unexpected end of file".into()));
        }
        Ok(&self.bytes[start..self.pos])
    }
}

fn parse_str<T: std::str::FromStr>(token: &[u8]) -> Option<T> {
    std::str::from_utf8(token).ok()?.parse().ok()
}

impl Source for Ascii<'_> {
    fn real(&mut self, ty: Scalar) -> Result<f64> {
        match ty {
            // Parsed as f32 directly: correctly rounded, and bit-exact for what writers print.
            Scalar::F32 => {
                let token = self.token()?;
                parse_str::<f32>(token)
                    .map(f64::from)
                    .ok_or_else(|| self.error(format!("bad float value {:?}", lossy(token))))
            }
            Scalar::F64 => {
                let token = self.token()?;
                parse_str::<f64>(token)
                    .ok_or_else(|| self.error(format!("bad double value {:?}", lossy(token))))
            }
            _ => self.integer(ty).map(|i| i as f64),
        }
    }

    fn integer(&mut self, ty: Scalar) -> Result<i64> {
        let token = self.token()?;
        let (lo, hi) = ty
            .int_range()
            .ok_or_else(|| self.error(format!("{ty:?} is not an integer type")))?;
        parse_i64(token)
            .filter(|i| (lo..=hi).contains(i))
            .ok_or_else(|| self.error(format!("bad {ty:?} value {:?}", lossy(token))))
    }

    fn skip(&mut self, _ty: Scalar, n: usize) -> Result<()> {
        // Values nobody reads are not checked; each still has to be there.
        for _ in 0..n {
            self.token()?;
        }
        Ok(())
    }

    fn line(&self) -> usize {
        self.token_line
    }

    fn error(&self, message: String) -> MeshIoError {
        MeshIoError::parse(self.path, self.token_line, message)
    }

    fn non_finite(&self, vertex: usize, value: f32) -> MeshIoError {
        self.error(format!(
            "vertex {vertex} has a non-finite coordinate ({value})"
        ))
    }

    fn remaining(&self) -> usize {
        self.bytes.len() - self.pos
    }

    fn trailing(&self) -> Option<String> {
        let rest = &self.bytes[self.pos..];
        rest.iter()
            .any(|b| !b.is_ascii_whitespace())
            .then(|| "data after the last element ignored".to_string())
    }
}

/// Binary data: packed scalars in one byte order.
pub(super) struct Binary<'a> {
    bytes: &'a [u8],
    pos: usize,
    big_endian: bool,
    path: &'a Path,
}

impl<'a> Binary<'a> {
    pub(super) fn new(bytes: &'a [u8], start: usize, big_endian: bool, path: &'a Path) -> Self {
        Self {
            bytes,
            pos: start.min(bytes.len()),
            big_endian,
            path,
        }
    }

    #[inline]
    fn take<const N: usize>(&mut self) -> Result<[u8; N]> {
        let chunk = self
            .bytes
            .get(self.pos..)
            .and_then(|rest| rest.first_chunk::<N>())
            .ok_or_else(|| self.error("unexpected end of file".into()))?;
        self.pos += N;
        Ok(*chunk)
    }
}

/// Decodes a byte array in the file's order.
macro_rules! decode {
    ($self:ident, $t:ty) => {{
        let b = $self.take()?;
        if $self.big_endian {
            <$t>::from_be_bytes(b)
        } else {
            <$t>::from_le_bytes(b)
        }
    }};
}

impl Source for Binary<'_> {
    #[inline]
    fn real(&mut self, ty: Scalar) -> Result<f64> {
        Ok(match ty {
            Scalar::F32 => f64::from(decode!(self, f32)),
            Scalar::F64 => decode!(self, f64),
            _ => self.integer(ty)? as f64,
        })
    }

    #[inline]
    fn integer(&mut self, ty: Scalar) -> Result<i64> {
        Ok(match ty {
            Scalar::I8 => decode!(self, i8).into(),
            Scalar::U8 => decode!(self, u8).into(),
            Scalar::I16 => decode!(self, i16).into(),
            Scalar::U16 => decode!(self, u16).into(),
            Scalar::I32 => decode!(self, i32).into(),
            Scalar::U32 => decode!(self, u32).into(),
            Scalar::F32 | Scalar::F64 => {
                return Err(self.error(format!("{ty:?} is not an integer type")));
            }
        })
    }

    fn skip(&mut self, ty: Scalar, n: usize) -> Result<()> {
        let end = n
            .checked_mul(ty.size())
            .and_then(|len| self.pos.checked_add(len))
            .filter(|&end| end <= self.bytes.len())
            .ok_or_else(|| self.error("unexpected end of file".into()))?;
        self.pos = end;
        Ok(())
    }

    fn line(&self) -> usize {
        0
    }

    fn error(&self, message: String) -> MeshIoError {
        MeshIoError::parse(self.path, 0, format!("{message} (at byte {})", self.pos))
    }

    fn non_finite(&self, vertex: usize, value: f32) -> MeshIoError {
        MeshIoError::NonFinite {
            path: self.path.into(),
            vertex,
            value,
        }
    }

    fn remaining(&self) -> usize {
        self.bytes.len() - self.pos
    }

    fn trailing(&self) -> Option<String> {
        let n = self.remaining();
        (n > 0).then(|| format!("{n} bytes after the last element ignored"))
    }
}
