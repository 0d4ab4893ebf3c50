//! The opened file and its data: buffers (the binary chunk, a data URI or a file beside the glTF file),
//! buffer views and accessors, each read checked against the bytes there are.

use std::cell::{Cell, OnceCell};
use std::collections::HashMap;
use std::path::{Component, Path, PathBuf};
use std::rc::Rc;

use base64::Engine as _;
use gltf::Gltf;
use gltf::accessor::{DataType, Dimensions};
use percent_encoding::percent_decode_str;

use super::validate::validate;
use super::{MAX_PLANT_BUFFER_BYTES, MAX_PLANT_JSON_BYTES, MAX_PLANT_TRIANGLES, PlantFileError};

/// A problem inside an accessor, before the primitive it belongs to is known.
pub(super) enum AccessorError {
    Plant(PlantFileError),
    Bad(String),
}

impl From<PlantFileError> for AccessorError {
    fn from(e: PlantFileError) -> Self {
        Self::Plant(e)
    }
}

/// An opened glTF file: its JSON checked, its buffers read when first asked for.
pub(super) struct Loader<'p> {
    pub(super) path: &'p Path,
    /// Reads the files the glTF names.
    pub(super) read: &'p super::PlantFileReader<'p>,
    pub(super) gltf: Gltf,
    /// Buffer data by index, read when first needed; buffers of the same source share it.
    buffers: Vec<OnceCell<Rc<Vec<u8>>>>,
    /// For each buffer, the first buffer of its source ([`source_key`]).
    first_of_source: Vec<usize>,
    /// Bytes read for the buffers so far (each source once), against
    /// [`MAX_PLANT_BUFFER_BYTES`].
    read_bytes: Cell<u64>,
}

/// What a buffer's bytes come from, buffers of the same key sharing one read: its URI, or the
/// binary chunk.
fn source_key<'a>(buffer: &gltf::Buffer<'a>) -> Option<&'a str> {
    match buffer.source() {
        gltf::buffer::Source::Bin => None,
        gltf::buffer::Source::Uri(uri) => Some(uri),
    }
}

impl<'p> Loader<'p> {
    pub(super) fn new(
        path: &'p Path,
        bytes: &[u8],
        read: &'p super::PlantFileReader<'p>,
    ) -> Result<Self, PlantFileError> {
        let not_gltf = |reason: String| PlantFileError::NotGltf {
            path: path.to_owned(),
            reason,
        };
        // The glb reader subtracts the header's size from its length field unchecked.
        if bytes.starts_with(b"glTF") {
            let length = bytes
                .get(8..12)
                .map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]));
            match length {
                None => return Err(not_gltf("the binary header is cut short".into())),
                Some(n) if n < 12 => {
                    return Err(not_gltf(format!(
                        "the binary header gives a length of {n} bytes"
                    )));
                }
                Some(_) => {}
            }
        }
        // Parsed, the JSON takes many times its size: its structure is counted first.
        let json = json_part(bytes);
        let structure = json_structure_bytes(json);
        if structure > MAX_PLANT_JSON_BYTES {
            return Err(PlantFileError::JsonTooLarge {
                path: path.to_owned(),
                bytes: structure,
                limit: MAX_PLANT_JSON_BYTES,
            });
        }
        let gltf =
            Gltf::from_slice_without_validation(bytes).map_err(|e| not_gltf(e.to_string()))?;
        validate(&gltf).map_err(not_gltf)?;
        // Every file the document names, used or not, before any is read.
        let root = gltf.as_json();
        let uris = root.buffers.iter().filter_map(|b| b.uri.as_deref());
        for uri in uris.chain(root.images.iter().filter_map(|i| i.uri.as_deref())) {
            if !uri.starts_with("data:") {
                file_name(uri).map_err(|reason| PlantFileError::BadUri {
                    path: path.to_owned(),
                    uri: uri.to_owned(),
                    reason,
                })?;
            }
        }
        // Buffers of one source are read once; the largest length declared for each source,
        // together, must fit the limit before anything is read.
        let mut first: HashMap<Option<&str>, (usize, u64)> = HashMap::new();
        let mut first_of_source = Vec::new();
        for buffer in gltf.buffers() {
            let length = buffer.length() as u64;
            let entry = first
                .entry(source_key(&buffer))
                .or_insert((buffer.index(), length));
            entry.1 = entry.1.max(length);
            first_of_source.push(entry.0);
        }
        let declared = first
            .values()
            .fold(0u64, |sum, &(_, length)| sum.saturating_add(length));
        if declared > MAX_PLANT_BUFFER_BYTES {
            return Err(PlantFileError::BuffersTooLarge {
                path: path.to_owned(),
                bytes: declared,
                limit: MAX_PLANT_BUFFER_BYTES,
            });
        }
        drop(first);
        let buffers = vec![OnceCell::new(); gltf.buffers().len()];
        Ok(Self {
            path,
            read,
            gltf,
            buffers,
            first_of_source,
            read_bytes: Cell::new(0),
        })
    }
}

impl Loader<'_> {
    /// The data of a buffer, read when first asked for (once for all the buffers of its source);
    /// refused once the buffers read pass [`MAX_PLANT_BUFFER_BYTES`] together.
    fn buffer(&self, index: usize) -> Result<&[u8], PlantFileError> {
        if self.buffers.get(index).is_some_and(|b| b.get().is_none()) {
            let buffer =
                self.gltf
                    .buffers()
                    .nth(index)
                    .ok_or_else(|| PlantFileError::BufferMissing {
                        path: self.path.to_owned(),
                        buffer: index,
                        reason: "no such buffer".into(),
                    })?;
            let missing = |reason: String| PlantFileError::BufferMissing {
                path: self.path.to_owned(),
                buffer: index,
                reason,
            };
            let first = self.first_of_source.get(index).copied().unwrap_or(index);
            let shared = match self.buffers.get(first).and_then(OnceCell::get) {
                Some(data) if first != index => Some(Rc::clone(data)),
                _ => None,
            };
            let data = match shared {
                Some(data) => data,
                None => {
                    let data = match buffer.source() {
                        gltf::buffer::Source::Bin => self
                            .gltf
                            .blob
                            .clone()
                            .ok_or_else(|| missing("the file has no binary chunk".into()))?,
                        gltf::buffer::Source::Uri(uri) => {
                            read_uri(self.path, uri, self.read).map_err(missing)?
                        }
                    };
                    let total = self.read_bytes.get().saturating_add(data.len() as u64);
                    if total > MAX_PLANT_BUFFER_BYTES {
                        return Err(PlantFileError::BuffersTooLarge {
                            path: self.path.to_owned(),
                            bytes: total,
                            limit: MAX_PLANT_BUFFER_BYTES,
                        });
                    }
                    self.read_bytes.set(total);
                    let data = Rc::new(data);
                    if first != index {
                        let _ = self.buffers[first].set(Rc::clone(&data));
                    }
                    data
                }
            };
            if data.len() < buffer.length() {
                return Err(PlantFileError::BufferTooShort {
                    path: self.path.to_owned(),
                    buffer: index,
                    len: data.len(),
                    needed: buffer.length(),
                });
            }
            let _ = self.buffers[index].set(data);
        }
        Ok(self
            .buffers
            .get(index)
            .and_then(|b| b.get())
            .map_or(&[], |data| data.as_slice()))
    }

    /// The bytes of a buffer view, checked against its buffer.
    pub(super) fn view_bytes(&self, view: &gltf::buffer::View) -> Result<&[u8], PlantFileError> {
        let index = view.buffer().index();
        let path = self.path.to_owned();
        let (start, length) = (view.offset(), view.length());
        let data = self.buffer(index)?;
        let end = start.saturating_add(length);
        data.get(start..end).ok_or(PlantFileError::BufferTooShort {
            path,
            buffer: index,
            len: data.len(),
            needed: end,
        })
    }

    /// An accessor's values, component by component, as f32 (integers normalised to 0..1 or
    /// -1..1 when the accessor says so or `normalize` asks).
    pub(super) fn read_accessor(
        &self,
        acc: &gltf::Accessor,
        name: &str,
        dims: &[Dimensions],
        normalize: bool,
    ) -> Result<Vec<f32>, AccessorError> {
        let dimensions = acc.dimensions();
        if !dims.contains(&dimensions) {
            return Err(AccessorError::Bad(format!(
                "{name} must be {}, not {dimensions:?}",
                dims.iter()
                    .map(|d| format!("{d:?}"))
                    .collect::<Vec<_>>()
                    .join(" or ")
            )));
        }
        let normalize = normalize || acc.normalized();
        let data_type = acc.data_type();
        let components = dimensions.multiplicity();
        let component_size = data_type.size();
        let element = components * component_size;
        let count = acc.count();
        // The vertex and triangle limits were checked against counts before; this guards the
        // allocation of an accessor that no limit counted.
        if count > MAX_PLANT_TRIANGLES * 3 {
            return Err(AccessorError::Bad(format!(
                "{name} has {count} entries, more than any plant within the limits needs"
            )));
        }
        let mut values = vec![0.0f32; count * components];
        if count == 0 {
            return Ok(values);
        }
        if let Some(view) = acc.view() {
            let stride = view.stride().unwrap_or(element);
            if stride < element {
                return Err(AccessorError::Bad(format!(
                    "{name}'s byte stride {stride} is less than its element size {element}"
                )));
            }
            let offset = acc.offset();
            let bytes = self.view_bytes(&view)?;
            let needed = stride
                .checked_mul(count - 1)
                .and_then(|x| x.checked_add(offset))
                .and_then(|x| x.checked_add(element));
            if needed.is_none_or(|needed| needed > bytes.len()) {
                return Err(AccessorError::Bad(format!(
                    "{name} reads past the end of buffer view {} ({} bytes)",
                    view.index(),
                    bytes.len()
                )));
            }
            for i in 0..count {
                let at = offset + i * stride;
                for c in 0..components {
                    values[i * components + c] =
                        component(&bytes[at + c * component_size..], data_type, normalize);
                }
            }
        }
        if let Some(sparse) = acc.sparse() {
            let sc = sparse.count();
            if sc > count {
                return Err(AccessorError::Bad(format!(
                    "{name} has {sc} sparse entries, more than its {count} entries"
                )));
            }
            let indices = sparse.indices();
            let index_size = indices.index_type().size();
            let index_type = match indices.index_type() {
                gltf::accessor::sparse::IndexType::U8 => DataType::U8,
                gltf::accessor::sparse::IndexType::U16 => DataType::U16,
                gltf::accessor::sparse::IndexType::U32 => DataType::U32,
            };
            let index_offset = indices.offset();
            let index_bytes = self.view_bytes(&indices.view())?.to_vec();
            let vals = sparse.values();
            let value_offset = vals.offset();
            let value_bytes = self.view_bytes(&vals.view())?;
            let fits = |offset: usize, size: usize, len: usize| {
                sc.checked_mul(size)
                    .and_then(|x| x.checked_add(offset))
                    .is_some_and(|end| end <= len)
            };
            if !fits(index_offset, index_size, index_bytes.len())
                || !fits(value_offset, element, value_bytes.len())
            {
                return Err(AccessorError::Bad(format!(
                    "{name}'s sparse data reads past the end of its buffer views"
                )));
            }
            for k in 0..sc {
                let target = component(
                    &index_bytes[index_offset + k * index_size..],
                    index_type,
                    false,
                );
                let target = target as usize;
                if target >= count {
                    return Err(AccessorError::Bad(format!(
                        "{name} has sparse index {target}, out of range for its {count} entries"
                    )));
                }
                let at = value_offset + k * element;
                for c in 0..components {
                    values[target * components + c] = component(
                        &value_bytes[at + c * component_size..],
                        data_type,
                        normalize,
                    );
                }
            }
        }
        Ok(values)
    }
}

/// One component at the start of `bytes` (the caller has checked there are enough).
fn component(bytes: &[u8], data_type: DataType, normalize: bool) -> f32 {
    let b = |n: usize| bytes.get(n).copied().unwrap_or(0);
    match data_type {
        DataType::I8 => {
            let v = b(0) as i8 as f32;
            if normalize { (v / 127.0).max(-1.0) } else { v }
        }
        DataType::U8 => {
            let v = b(0) as f32;
            if normalize { v / 255.0 } else { v }
        }
        DataType::I16 => {
            let v = i16::from_le_bytes([b(0), b(1)]) as f32;
            if normalize {
                (v / 32767.0).max(-1.0)
            } else {
                v
            }
        }
        DataType::U16 => {
            let v = u16::from_le_bytes([b(0), b(1)]) as f32;
            if normalize { v / 65535.0 } else { v }
        }
        DataType::U32 => u32::from_le_bytes([b(0), b(1), b(2), b(3)]) as f32,
        DataType::F32 => f32::from_le_bytes([b(0), b(1), b(2), b(3)]),
    }
}

/// The JSON the glTF parser reads from a file: all of a `.gltf`, the first chunk of a `.glb`
/// (as far as the file holds it).
fn json_part(bytes: &[u8]) -> &[u8] {
    if !bytes.starts_with(b"glTF") {
        return bytes;
    }
    let length = bytes
        .get(12..16)
        .map_or(0, |b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]) as usize);
    let start = 20.min(bytes.len());
    &bytes[start..start.saturating_add(length).min(bytes.len())]
}

/// The bytes of `json` outside its strings' contents, whitespace left out: what the parser
/// makes objects, arrays, numbers and keys of. A string's quotes count; what lies between them
/// (escapes included) does not. Bytes that are not JSON count like structure.
fn json_structure_bytes(json: &[u8]) -> u64 {
    let mut count = 0u64;
    let mut in_string = false;
    let mut escaped = false;
    for &b in json {
        if in_string {
            if escaped {
                escaped = false;
            } else if b == b'\\' {
                escaped = true;
            } else if b == b'"' {
                in_string = false;
                count += 1;
            }
        } else if !matches!(b, b' ' | b'\t' | b'\n' | b'\r') {
            in_string = b == b'"';
            count += 1;
        }
    }
    count
}

/// The file a URI that is not a data URI names, percent-decoded, relative to the glTF file's
/// folder: it must stay in that folder or below it, so that a plant reads no file beyond its
/// world's (on disk or over HTTP). Refused: a `..` segment (percent-encoded or not), an
/// absolute path, a scheme (any `:`), a backslash (a separator on some systems and servers).
fn file_name(uri: &str) -> Result<PathBuf, String> {
    let name = percent_decode_str(uri)
        .decode_utf8()
        .map_err(|_| "it is not UTF-8 once percent-decoded".to_owned())?;
    if name.contains(':') {
        return Err(
            "it has a scheme or a drive: only names relative to the glTF file are read".into(),
        );
    }
    if name.contains('\\') {
        return Err("it has a backslash (a URI's folders are separated by /)".into());
    }
    let relative = Path::new(name.as_ref());
    for c in relative.components() {
        match c {
            Component::Normal(_) | Component::CurDir => {}
            Component::ParentDir => {
                return Err(
                    "it has a .. segment once percent-decoded: it leaves the glTF file's folder"
                        .into(),
                );
            }
            Component::RootDir | Component::Prefix(_) => {
                return Err(
                    "it is an absolute path: only names relative to the glTF file are read".into(),
                );
            }
        }
    }
    Ok(relative.to_owned())
}

/// The bytes a glTF URI names: a base64 data URI, or a file in the glTF file's folder or below
/// it ([`file_name`]).
pub(super) fn read_uri(
    gltf_path: &Path,
    uri: &str,
    read: &super::PlantFileReader<'_>,
) -> Result<Vec<u8>, String> {
    if let Some(rest) = uri.strip_prefix("data:") {
        let Some((header, data)) = rest.split_once(',') else {
            return Err("a data URI without a comma".into());
        };
        if !header.ends_with(";base64") {
            return Err("a data URI that is not base64".into());
        }
        return base64::engine::general_purpose::STANDARD
            .decode(data)
            .map_err(|e| format!("a data URI with bad base64: {e}"));
    }
    let relative =
        file_name(uri).map_err(|reason| format!("the URI {uri:?} is refused: {reason}"))?;
    let file = gltf_path.parent().unwrap_or(Path::new(".")).join(relative);
    read(&file).map_err(|e| format!("cannot read {}: {e}", file.display()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn normalised_components() {
        assert_eq!(component(&[255], DataType::U8, true), 1.0);
        assert_eq!(component(&[0x80], DataType::I8, true), -1.0);
        assert_eq!(component(&[0xff, 0xff], DataType::U16, true), 1.0);
        assert_eq!(component(&[7, 0, 0, 0], DataType::U32, false), 7.0);
    }

    #[test]
    fn json_structure_leaves_out_strings_and_whitespace() {
        assert_eq!(json_structure_bytes(b"{}"), 2);
        assert_eq!(json_structure_bytes(b" {\n\t\"uri\" : \"a b\" }\r\n"), 7);
        // An escaped quote or backslash stays inside its string.
        assert_eq!(json_structure_bytes(br#"["a\"],[", "\\", 1]"#), 9);
        // A string left open counts its opening quote only.
        assert_eq!(json_structure_bytes(br#"[1,"abc"#), 4);
    }

    #[test]
    fn json_part_of_a_glb_is_its_first_chunk() {
        let mut glb = b"glTF\x02\0\0\0\0\0\0\0\x04\0\0\0JSON[1] ".to_vec();
        glb.extend_from_slice(b"\x04\0\0\0BIN\0[[[[");
        assert_eq!(json_part(&glb), b"[1] ");
        assert_eq!(json_part(b"{\"a\":1}"), b"{\"a\":1}");
        // A chunk longer than the file: as much as it holds; a header cut short: nothing.
        assert_eq!(json_part(&glb[..22]), b"[1");
        assert_eq!(json_part(&glb[..14]), b"");
    }

    #[test]
    fn file_names_stay_in_the_gltf_files_folder() {
        for ok in [
            "a.bin",
            "./a.bin",
            "sub/a.bin",
            "sub%2Fa.bin",
            "a..b.bin",
            "...",
            "%252e%252e/a",
        ] {
            assert!(file_name(ok).is_ok(), "{ok}");
        }
        for bad in [
            "..",
            "../a.bin",
            "sub/../../a.bin",
            "..%2Fa.bin",
            "%2e%2e/a.bin",
            "%2E%2E%2Fa.bin",
            "sub/%2e%2e",
            "..\\a.bin",
            "..%5ca.bin",
            "/etc/passwd",
            "%2Fetc%2Fpasswd",
            "file:a.bin",
            "C:a.bin",
            "%ff.bin",
        ] {
            assert!(file_name(bad).is_err(), "{bad}");
        }
    }
}
