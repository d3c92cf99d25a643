//! Buffers: the GLB `BIN` chunk, `data:` URIs and files relative to the document, each cut to
//! its `byteLength` and loaded on first use.

use super::Source;
use crate::error::{MeshIoError, Result};
use crate::glb::container::{decode_data_uri, has_scheme, percent_decode};
use std::borrow::Cow;
use std::path::{Path, PathBuf};

impl<'a> Source<'a> {
    /// Buffer `index`, cut to its `byteLength`, loaded on first use.
    pub(super) fn buffer(&self, index: usize, what: &str) -> Result<&[u8]> {
        let cell = self
            .buffers
            .get(index)
            .ok_or_else(|| self.error(format!("{what}: buffer {index} does not exist")))?;
        if let Some(data) = cell.get() {
            return Ok(data);
        }
        let data = self.load_buffer(index)?;
        Ok(cell.get_or_init(|| data))
    }

    fn load_buffer(&self, index: usize) -> Result<Cow<'a, [u8]>> {
        let Some(buffer) = self.root.buffers.get(index) else {
            return Err(self.error(format!("buffer {index} does not exist")));
        };
        let data: Cow<'a, [u8]> = match buffer.uri.as_deref() {
            None if index == 0 => Cow::Borrowed(self.bin.ok_or_else(|| {
                self.error("buffer 0 has no uri and there is no GLB BIN chunk".into())
            })?),
            None => return Err(self.error(format!("buffer {index} has no uri"))),
            Some(uri) if uri.starts_with("data:") => Cow::Owned(
                decode_data_uri(uri).map_err(|m| self.error(format!("buffer {index}: {m}")))?,
            ),
            Some(uri) if has_scheme(uri) => {
                return Err(self.error(format!(
                    "buffer {index}: unsupported URI {:?} (only relative file paths and \
                     data:…;base64, URIs are read)",
                    uri.chars().take(60).collect::<String>()
                )));
            }
            Some(uri) => {
                let relative =
                    percent_decode(uri).map_err(|m| self.error(format!("buffer {index}: {m}")))?;
                let file = self
                    .path
                    .parent()
                    .map_or_else(PathBuf::new, Path::to_path_buf)
                    .join(relative);
                Cow::Owned(std::fs::read(&file).map_err(|e| MeshIoError::io(&file, e))?)
            }
        };
        let length = buffer.byte_length.0;
        if (data.len() as u64) < length {
            return Err(self.error(format!(
                "buffer {index} declares {length} bytes but holds {}",
                data.len()
            )));
        }
        let length = length as usize;
        Ok(match data {
            Cow::Borrowed(bytes) => Cow::Borrowed(&bytes[..length]),
            Cow::Owned(mut bytes) => {
                bytes.truncate(length);
                Cow::Owned(bytes)
            }
        })
    }
}
