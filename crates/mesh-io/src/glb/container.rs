//! Where a glTF's bytes are: the GLB container's chunks, and buffer URIs (relative paths with
//! `%XX` escapes, `data:` URIs in base64).
//!
//! The GLB header is parsed here rather than by `gltf::Glb::from_slice`, which subtracts 12 from
//! the header's length field unchecked (a panic in debug builds for a length below 12).

/// Splits a GLB into its JSON chunk and its BIN chunk (if any); unknown chunks are skipped, as
/// the spec asks.
pub(super) fn split_glb(bytes: &[u8]) -> std::result::Result<(&[u8], Option<&[u8]>), String> {
    let word = |at: usize| {
        bytes
            .get(at..at + 4)
            .map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
    };
    let (Some(version), Some(length)) = (word(4), word(8)) else {
        return Err(format!("GLB header truncated ({} bytes)", bytes.len()));
    };
    if version != 2 {
        return Err(format!("GLB version {version} is not supported (2 only)"));
    }
    let length = length as usize;
    if length < 12 || length > bytes.len() {
        return Err(format!(
            "GLB header gives a length of {length} bytes but the file has {}",
            bytes.len()
        ));
    }
    let (mut at, mut json, mut bin) = (12, None, None);
    while at < length {
        let (Some(chunk_length), Some(kind)) = (word(at), bytes.get(at + 4..at + 8)) else {
            return Err(format!("GLB chunk header at byte {at} is truncated"));
        };
        let start = at + 8;
        let end = start
            .checked_add(chunk_length as usize)
            .filter(|&end| end <= length)
            .ok_or_else(|| {
                format!("GLB chunk at byte {at} ({chunk_length} bytes) overruns the file")
            })?;
        let data = &bytes[start..end];
        match kind {
            b"JSON" if json.is_none() && at == 12 => json = Some(data),
            _ if json.is_none() => return Err("the first GLB chunk is not JSON".into()),
            b"JSON" => return Err("the GLB has a second JSON chunk".into()),
            b"BIN\0" if bin.is_none() => bin = Some(data),
            b"BIN\0" => return Err("the GLB has a second BIN chunk".into()),
            _ => {}
        }
        at = end;
    }
    Ok((json.ok_or("the GLB has no JSON chunk")?, bin))
}

/// Whether `uri` starts with a scheme (`http:`, `file:`, …) rather than being a relative path.
pub(super) fn has_scheme(uri: &str) -> bool {
    match uri.split_once(':') {
        Some((scheme, _)) => {
            scheme.starts_with(|c: char| c.is_ascii_alphabetic())
                && scheme
                    .chars()
                    .all(|c| c.is_ascii_alphanumeric() || "+-.".contains(c))
        }
        None => false,
    }
}

/// Decodes `%XX` escapes of a relative URI.
pub(super) fn percent_decode(uri: &str) -> std::result::Result<String, String> {
    let bytes = uri.as_bytes();
    let mut out = Vec::with_capacity(bytes.len());
    let mut i = 0;
    while i < bytes.len() {
        if bytes[i] == b'%' {
            let hex = bytes
                .get(i + 1..i + 3)
                .and_then(|h| std::str::from_utf8(h).ok())
                .and_then(|h| u8::from_str_radix(h, 16).ok())
                .ok_or_else(|| format!("bad %-escape in URI {uri:?}"))?;
            out.push(hex);
            i += 3;
        } else {
            out.push(bytes[i]);
            i += 1;
        }
    }
    String::from_utf8(out).map_err(|_| format!("URI {uri:?} is not UTF-8 once decoded"))
}

/// The bytes of a `data:[<media type>];base64,<data>` URI.
pub(super) fn decode_data_uri(uri: &str) -> std::result::Result<Vec<u8>, String> {
    let (header, payload) = uri.split_once(',').ok_or("data: URI without a comma")?;
    if !header.ends_with(";base64") {
        return Err("only base64 data: URIs are supported".into());
    }
    base64_decode(payload)
}

/// Standard base64 (RFC 4648 §4; the URL-safe `-` and `_` are accepted too), `=` padding
/// optional.
fn base64_decode(text: &str) -> std::result::Result<Vec<u8>, String> {
    let body = text.trim_end_matches('=');
    if text.len() - body.len() > 2 || body.len() % 4 == 1 {
        return Err("truncated or badly padded base64".into());
    }
    let mut out = Vec::with_capacity(body.len() / 4 * 3 + 2);
    let (mut acc, mut bits) = (0u32, 0u32);
    for (i, c) in body.bytes().enumerate() {
        let value = match c {
            b'A'..=b'Z' => c - b'A',
            b'a'..=b'z' => c - b'a' + 26,
            b'0'..=b'9' => c - b'0' + 52,
            b'+' | b'-' => 62,
            b'/' | b'_' => 63,
            _ => return Err(format!("invalid base64 character at position {i}")),
        };
        acc = (acc << 6) | u32::from(value);
        bits += 6;
        if bits >= 8 {
            bits -= 8;
            out.push((acc >> bits) as u8);
            acc &= (1 << bits) - 1;
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A plain reference encoder, to test the decoder on every length and byte value.
    fn encode(bytes: &[u8]) -> String {
        const ALPHABET: &[u8] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
        let mut out = String::new();
        for chunk in bytes.chunks(3) {
            let b = [
                chunk[0],
                *chunk.get(1).unwrap_or(&0),
                *chunk.get(2).unwrap_or(&0),
            ];
            let n = (u32::from(b[0]) << 16) | (u32::from(b[1]) << 8) | u32::from(b[2]);
            for k in 0..4 {
                if k <= chunk.len() {
                    out.push(ALPHABET[(n >> (18 - 6 * k) & 63) as usize] as char);
                } else {
                    out.push('=');
                }
            }
        }
        out
    }

    #[test]
    fn base64_round_trips_every_length() {
        let bytes: Vec<u8> = (0..=255u8).chain((0..=255u8).rev()).collect();
        for len in 0..40 {
            let data = &bytes[len * 7 % 200..][..len];
            let text = encode(data);
            assert_eq!(base64_decode(&text).unwrap(), data, "{text}");
            assert_eq!(base64_decode(text.trim_end_matches('=')).unwrap(), data);
        }
        assert_eq!(base64_decode("TWFu").unwrap(), b"Man");
        assert_eq!(base64_decode("TWE=").unwrap(), b"Ma");
        assert!(base64_decode("TWFu!").is_err());
        assert!(base64_decode("TWFuT").is_err());
        assert!(base64_decode("T===").is_err());
    }

    #[test]
    fn uri_helpers() {
        assert!(has_scheme("http://x/y.bin"));
        assert!(has_scheme("file:y.bin"));
        assert!(!has_scheme("y.bin"));
        assert!(!has_scheme("sub dir/y.bin"));
        assert_eq!(percent_decode("a%20b%2Fc.bin").unwrap(), "a b/c.bin");
        assert!(percent_decode("a%2").is_err());
        assert!(percent_decode("a%zz").is_err());
        assert_eq!(
            decode_data_uri("data:application/octet-stream;base64,AAEC").unwrap(),
            [0, 1, 2]
        );
        assert!(decode_data_uri("data:text/plain,hello").is_err());
    }

    #[test]
    fn glb_container_errors() {
        assert!(split_glb(b"glTF").is_err());
        let mut header = b"glTF".to_vec();
        header.extend(2u32.to_le_bytes());
        header.extend(4u32.to_le_bytes()); // shorter than the header itself
        assert!(split_glb(&header).unwrap_err().contains("length of 4"));
        let mut glb = b"glTF".to_vec();
        glb.extend(2u32.to_le_bytes());
        glb.extend(28u32.to_le_bytes());
        glb.extend(4u32.to_le_bytes());
        glb.extend(b"JSON{}  ");
        glb.extend([0u8; 4]); // a chunk header cut short
        assert!(split_glb(&glb).unwrap_err().contains("truncated"));
        glb.truncate(24);
        glb[8] = 24;
        let (json, bin) = split_glb(&glb).unwrap();
        assert_eq!((json, bin), (&b"{}  "[..], None));
    }
}
