//! Mitsuba's `serialized` triangle-mesh format: reading one mesh of a file by its `shape_index`, and writing.
//!
//! A file is a sequence of meshes followed by a dictionary. Each mesh is a little-endian header (`u16`
//! 0x041C, `u16` version 3 or 4) and a zlib stream holding: `u32` flags (0x1 vertex normals, 0x2 texture
//! coordinates, 0x8 vertex colours, 0x10 face normals, 0x1000 single or 0x2000 double precision), in version 4
//! a NUL-terminated name, `u64` vertex count, `u64` triangle count, then the positions, the normals, the
//! texture coordinates and the colours present, each as an array over the vertices, and the `u32` triangle
//! indices. The dictionary is each mesh's byte offset (`u64` in version 4, `u32` in version 3) and the `u32`
//! number of meshes. The zlib checksum of each mesh is checked. Every count is checked against the file's size before anything is allocated, so a
//! truncated or hostile file is refused with an error, never a panic or a huge allocation.

use flate2::read::ZlibDecoder;
use std::io::{Read, Write};
use std::path::Path;

const MAGIC: u16 = 0x041C;
const FLAG_NORMALS: u32 = 0x0001;
const FLAG_TEXCOORDS: u32 = 0x0002;
const FLAG_COLORS: u32 = 0x0008;
const FLAG_FACE_NORMALS: u32 = 0x0010;
const FLAG_SINGLE: u32 = 0x1000;
const FLAG_DOUBLE: u32 = 0x2000;
/// DEFLATE expands at most about 1032-fold: a mesh claiming more data than this allows is refused.
const MAX_EXPANSION: u64 = 1032;
/// The longest mesh name read.
const MAX_NAME_BYTES: usize = 1 << 16;

/// A triangle mesh as stored in a serialized file.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct SerializedMesh {
    /// The mesh's name (empty in version 3 files).
    pub name: String,
    pub positions: Vec<[f32; 3]>,
    /// Per-vertex normals as stored, when the file has them (not always of unit length: Mitsuba normalises them
    /// after applying `to_world`).
    pub normals: Option<Vec<[f32; 3]>>,
    /// Per-vertex texture coordinates, when the file has them.
    pub uvs: Option<Vec<[f32; 2]>>,
    /// Vertex indices, three per triangle, each below the vertex count.
    pub triangles: Vec<[u32; 3]>,
    /// The file asks for faceted shading (flag 0x10), as `face_normals="true"` does.
    pub face_normals: bool,
}

/// Why a serialized file cannot be read.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[error("{0}")]
pub struct SerializedError(String);

fn fail<T>(message: impl Into<String>) -> Result<T, SerializedError> {
    Err(SerializedError(message.into()))
}

/// The number of meshes in a serialized file, from its dictionary.
pub fn mesh_count(bytes: &[u8]) -> Result<u32, SerializedError> {
    let version = header(bytes, 0)?;
    dictionary(bytes, version).map(|offsets| offsets.len() as u32)
}

/// Reads the mesh `shape_index` (0 is the first) of the serialized file at `path`.
pub fn read_serialized_file(path: &Path, shape_index: u32) -> Result<SerializedMesh, SerializedError> {
    let bytes = std::fs::read(path).map_err(|e| SerializedError(format!("cannot read {}: {e}", path.display())))?;
    read_serialized(&bytes, shape_index).map_err(|e| SerializedError(format!("{}: {}", path.display(), e.0)))
}

/// Reads the mesh `shape_index` (0 is the first) of a serialized file's bytes.
pub fn read_serialized(bytes: &[u8], shape_index: u32) -> Result<SerializedMesh, SerializedError> {
    let version = header(bytes, 0)?;
    let offset = if shape_index == 0 {
        0
    } else {
        let offsets = dictionary(bytes, version)?;
        let Some(&offset) = offsets.get(shape_index as usize) else {
            return fail(format!("shape_index {shape_index} is out of range: the file holds {} meshes", offsets.len()));
        };
        if offset.checked_add(4).is_none_or(|end| end > bytes.len() as u64) {
            return fail(format!(
                "the dictionary places mesh {shape_index} at byte {offset}, past the end of the file"
            ));
        }
        offset as usize
    };
    let version = header(bytes, offset)?;
    read_mesh(&bytes[offset + 4..], version)
        .map_err(|e| SerializedError(format!("mesh {shape_index} (at byte {offset}): {}", e.0)))
}

/// Checks the header at `offset` and returns its version.
fn header(bytes: &[u8], offset: usize) -> Result<u16, SerializedError> {
    let Some(head) = bytes.get(offset..offset + 4) else {
        return fail("the file ends inside a mesh header: it is truncated or not a serialized mesh");
    };
    let magic = u16::from_le_bytes([head[0], head[1]]);
    let version = u16::from_le_bytes([head[2], head[3]]);
    if magic != MAGIC {
        return fail(format!("not a serialized mesh: the header is {magic:#06x}, not {MAGIC:#06x}"));
    }
    if version != 3 && version != 4 {
        return fail(format!("serialized format version {version}: versions 3 and 4 are read"));
    }
    Ok(version)
}

/// The mesh offsets listed at the end of the file.
fn dictionary(bytes: &[u8], version: u16) -> Result<Vec<u64>, SerializedError> {
    let len = bytes.len();
    if len < 4 {
        return fail("the file is too short to hold the dictionary of meshes");
    }
    let count = u32::from_le_bytes(bytes[len - 4..].try_into().expect("4 bytes")) as usize;
    let entry = if version == 4 { 8 } else { 4 };
    let table_len = count.checked_mul(entry).filter(|&n| n + 4 <= len);
    let Some(table_len) = table_len.filter(|_| count > 0) else {
        return fail(format!("the dictionary claims {count} meshes, which the file's {len} bytes cannot hold"));
    };
    let table = &bytes[len - 4 - table_len..len - 4];
    Ok(table
        .chunks_exact(entry)
        .map(|c| {
            if entry == 8 {
                u64::from_le_bytes(c.try_into().expect("8"))
            } else {
                u32::from_le_bytes(c.try_into().expect("4")) as u64
            }
        })
        .collect())
}

/// Reads the compressed body of one mesh.
fn read_mesh(compressed: &[u8], version: u16) -> Result<SerializedMesh, SerializedError> {
    let mut stream = Body { decoder: ZlibDecoder::new(compressed) };
    let flags = stream.u32()?;
    let double = match (flags & FLAG_SINGLE != 0, flags & FLAG_DOUBLE != 0) {
        (true, false) => false,
        (false, true) => true,
        _ => return fail(format!("the flags {flags:#x} give neither single nor double precision (or both)")),
    };
    let name = if version == 4 { stream.name()? } else { String::new() };
    let vertex_count = stream.u64()?;
    let triangle_count = stream.u64()?;
    if vertex_count > u32::MAX as u64 {
        return fail(format!("{vertex_count} vertices: meshes over 2^32 vertices (64-bit indices) are not read"));
    }
    let float_size = if double { 8 } else { 4 };
    let mut floats_per_vertex = 3;
    for (flag, n) in [(FLAG_NORMALS, 3), (FLAG_TEXCOORDS, 2), (FLAG_COLORS, 3)] {
        if flags & flag != 0 {
            floats_per_vertex += n;
        }
    }
    let needed = vertex_count
        .checked_mul(floats_per_vertex * float_size)
        .and_then(|v| triangle_count.checked_mul(12).and_then(|t| v.checked_add(t)));
    let limit = (compressed.len() as u64).saturating_mul(MAX_EXPANSION) + 4096;
    if needed.is_none_or(|n| n > limit) {
        return fail(format!(
            "{vertex_count} vertices and {triangle_count} triangles cannot come from {} compressed bytes: the file is \
             truncated or damaged",
            compressed.len()
        ));
    }
    let n = vertex_count as usize;
    let positions = stream.vectors::<3>(n, double)?;
    let normals = if flags & FLAG_NORMALS != 0 { Some(stream.vectors::<3>(n, double)?) } else { None };
    let uvs = if flags & FLAG_TEXCOORDS != 0 { Some(stream.vectors::<2>(n, double)?) } else { None };
    if flags & FLAG_COLORS != 0 {
        // Vertex colours are skipped, as Mitsuba does.
        stream.vectors::<3>(n, double)?;
    }
    let mut triangles = Vec::with_capacity(triangle_count as usize);
    let mut raw = [0u8; 12];
    for t in 0..triangle_count {
        stream.exact(&mut raw, "triangle indices")?;
        let triangle = [0, 1, 2].map(|k| u32::from_le_bytes(raw[4 * k..4 * k + 4].try_into().expect("4")));
        if let Some(&bad) = triangle.iter().find(|&&i| i as u64 >= vertex_count) {
            return fail(format!("triangle {t} names vertex {bad} of {vertex_count}"));
        }
        triangles.push(triangle);
    }
    stream.end()?;
    Ok(SerializedMesh { name, positions, normals, uvs, triangles, face_normals: flags & FLAG_FACE_NORMALS != 0 })
}

struct Body<'a> {
    decoder: ZlibDecoder<&'a [u8]>,
}

impl Body<'_> {
    fn exact(&mut self, buf: &mut [u8], what: &str) -> Result<(), SerializedError> {
        self.decoder.read_exact(buf).map_err(|e| match e.kind() {
            std::io::ErrorKind::UnexpectedEof => {
                SerializedError(format!("the mesh data ends inside its {what}: truncated"))
            }
            _ => SerializedError(format!("the compressed mesh data is damaged in its {what}: {e}")),
        })
    }

    /// Checks that the zlib stream ends here, which also checks its Adler-32 checksum over the data read.
    fn end(&mut self) -> Result<(), SerializedError> {
        match self.decoder.read(&mut [0u8; 1]) {
            Ok(0) => Ok(()),
            Ok(_) => fail("the compressed mesh data goes on past its triangles: the counts are wrong"),
            Err(e) => fail(format!("the compressed mesh data is damaged: {e}")),
        }
    }

    fn u32(&mut self) -> Result<u32, SerializedError> {
        let mut b = [0u8; 4];
        self.exact(&mut b, "header")?;
        Ok(u32::from_le_bytes(b))
    }

    fn u64(&mut self) -> Result<u64, SerializedError> {
        let mut b = [0u8; 8];
        self.exact(&mut b, "header")?;
        Ok(u64::from_le_bytes(b))
    }

    fn name(&mut self) -> Result<String, SerializedError> {
        let mut name = Vec::new();
        let mut b = [0u8; 1];
        loop {
            self.exact(&mut b, "name")?;
            if b[0] == 0 {
                break;
            }
            if name.len() == MAX_NAME_BYTES {
                return fail(format!("the mesh name is longer than {MAX_NAME_BYTES} bytes"));
            }
            name.push(b[0]);
        }
        Ok(String::from_utf8_lossy(&name).into_owned())
    }

    fn vectors<const N: usize>(&mut self, count: usize, double: bool) -> Result<Vec<[f32; N]>, SerializedError> {
        let size = if double { 8 } else { 4 };
        let mut out = Vec::with_capacity(count);
        let mut raw = [0u8; 24];
        for _ in 0..count {
            let raw = &mut raw[..N * size];
            self.exact(raw, "vertex data")?;
            out.push(std::array::from_fn(|k| {
                let c = &raw[k * size..(k + 1) * size];
                if double {
                    f64::from_le_bytes(c.try_into().expect("8")) as f32
                } else {
                    f32::from_le_bytes(c.try_into().expect("4"))
                }
            }));
        }
        Ok(out)
    }
}

/// Writes meshes as a version 4 serialized file with its dictionary, in single or double precision. Refuses a
/// mesh whose normals or uvs do not have one entry per position, or whose triangles name a missing vertex.
pub fn write_serialized(meshes: &[SerializedMesh], double_precision: bool) -> Result<Vec<u8>, SerializedError> {
    let mut out = Vec::new();
    let mut offsets = Vec::with_capacity(meshes.len());
    for (index, mesh) in meshes.iter().enumerate() {
        let n = mesh.positions.len();
        if mesh.normals.as_ref().is_some_and(|v| v.len() != n) || mesh.uvs.as_ref().is_some_and(|v| v.len() != n) {
            return fail(format!("mesh {index}: normals and uvs need one entry per position ({n})"));
        }
        if mesh.triangles.iter().flatten().any(|&i| i as usize >= n) {
            return fail(format!("mesh {index}: a triangle names a vertex beyond the {n} positions"));
        }
        offsets.push(out.len() as u64);
        out.extend_from_slice(&MAGIC.to_le_bytes());
        out.extend_from_slice(&4u16.to_le_bytes());
        let mut body = Vec::new();
        let mut flags = if double_precision { FLAG_DOUBLE } else { FLAG_SINGLE };
        if mesh.normals.is_some() {
            flags |= FLAG_NORMALS;
        }
        if mesh.uvs.is_some() {
            flags |= FLAG_TEXCOORDS;
        }
        if mesh.face_normals {
            flags |= FLAG_FACE_NORMALS;
        }
        body.extend_from_slice(&flags.to_le_bytes());
        body.extend_from_slice(mesh.name.as_bytes());
        body.push(0);
        body.extend_from_slice(&(mesh.positions.len() as u64).to_le_bytes());
        body.extend_from_slice(&(mesh.triangles.len() as u64).to_le_bytes());
        let mut floats = |values: &mut dyn Iterator<Item = f32>| {
            for v in values {
                if double_precision {
                    body.extend_from_slice(&(v as f64).to_le_bytes());
                } else {
                    body.extend_from_slice(&v.to_le_bytes());
                }
            }
        };
        floats(&mut mesh.positions.iter().flatten().copied());
        if let Some(normals) = &mesh.normals {
            floats(&mut normals.iter().flatten().copied());
        }
        if let Some(uvs) = &mesh.uvs {
            floats(&mut uvs.iter().flatten().copied());
        }
        for index in mesh.triangles.iter().flatten() {
            body.extend_from_slice(&index.to_le_bytes());
        }
        let mut encoder = flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::default());
        encoder.write_all(&body).expect("writing to memory");
        out.extend_from_slice(&encoder.finish().expect("writing to memory"));
    }
    for offset in &offsets {
        out.extend_from_slice(&offset.to_le_bytes());
    }
    out.extend_from_slice(&(meshes.len() as u32).to_le_bytes());
    Ok(out)
}
