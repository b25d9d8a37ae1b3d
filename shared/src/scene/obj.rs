//! Wavefront OBJ meshes, read in parallel into one indexed mesh: the subset a renderer needs. It reads `v x y z`
//! (a `w` or an `r g b` after the coordinates is ignored), `vn x y z`, `vt u [v [w]]` (v is 0 when left out, w
//! ignored) and `f` with corners `v`, `v/vt`, `v//vn` or `v/vt/vn`, 1-based or negative (counting back from the
//! lines read so far), polygons fanned into triangles in tobj's order. Every other statement (`o`, `g`, `s`,
//! `usemtl`, `mtllib`, `l`, `p`, unknown ones), comments (from a word that starts with `#` to the end of its
//! line), blank lines, tabs and `\r\n` endings are skipped; `o` and `g` lines still split the mesh into named
//! parts as tobj splits it into models, which errors about a mesh's triangles name. As with tobj, the `vt`
//! (`vn`) indices of a file without `vt` (`vn`) lines are not read.
//!
//! A mesh of ten million triangles is a 400 MB text, which one thread takes seconds to read. The bytes are split
//! at line ends into chunks of a few megabytes, and two parallel passes read them: the first counts each chunk's
//! `v`, `vt` and `vn` lines, whose running totals then resolve negative indices and check every index while the
//! second pass parses the chunks; the chunks' lists are then joined in order.

use glam::{Vec2, Vec3};
use rayon::prelude::*;
use std::ops::Range;

/// The index a face corner gives where it gives no texture coordinate or normal.
pub const NONE: u32 = u32::MAX;

/// Bytes a chunk holds at most, about: enough chunks for rayon to even out the threads' work, few enough that
/// joining their lists costs little.
const CHUNK_BYTES: usize = 4 << 20;

/// Bytes a chunk holds at least: files below it are read on one thread.
const MIN_CHUNK_BYTES: usize = 64 << 10;

/// An OBJ file's mesh, indexed as the file indexes it: every triangle names its corners' position, texture
/// coordinate and normal by their index in the lists of `v`, `vt` and `vn` lines.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ObjMesh {
    /// The `v` lines' coordinates, in order.
    pub positions: Vec<Vec3>,
    /// The `vt` lines' (u, v), as written.
    pub texcoords: Vec<Vec2>,
    /// The `vn` lines' vectors, as written.
    pub normals: Vec<Vec3>,
    /// Each triangle's corners' indices into `positions`, in file order.
    pub triangles: Vec<[u32; 3]>,
    /// Each triangle's corners' indices into `texcoords`, [`NONE`] where a corner names none; empty when no corner
    /// names one.
    pub triangle_texcoords: Vec<[u32; 3]>,
    /// Each triangle's corners' indices into `normals`, [`NONE`] where a corner names none; empty when no corner
    /// names one.
    pub triangle_normals: Vec<[u32; 3]>,
    /// The parts `o` and `g` lines split the triangles into, in order, as tobj splits them into models; parts
    /// without triangles are left out.
    pub objects: Vec<ObjObject>,
}

/// A run of triangles under one `o` or `g` name.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ObjObject {
    /// The rest of the `o` or `g` line, trimmed, as tobj names its models ("unnamed_object" when empty or
    /// before any such line).
    pub name: String,
    /// The triangles' indices in [`ObjMesh::triangles`].
    pub triangles: Range<usize>,
}

/// How many of some triangles' corners name a texture coordinate (or a normal).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Coverage {
    None,
    Partial,
    All,
}

/// How many corners of the triangles `triangles` name an index in `list`, [`ObjMesh::triangle_texcoords`] or
/// [`ObjMesh::triangle_normals`]; `None` for no triangles.
pub fn coverage(list: &[[u32; 3]], triangles: Range<usize>) -> Coverage {
    let Some(list) = list.get(triangles).filter(|l| !l.is_empty()) else { return Coverage::None };
    if list.par_iter().all(|t| !t.contains(&NONE)) {
        Coverage::All
    } else if list.par_iter().any(|t| *t != [NONE; 3]) {
        Coverage::Partial
    } else {
        Coverage::None
    }
}

/// Why an OBJ file cannot be read, at its 1-based line.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("line {line}: {problem}")]
pub struct ObjError {
    /// The line of the statement, from 1.
    pub line: usize,
    pub problem: ObjProblem,
}

/// What is wrong with a line of an OBJ file.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum ObjProblem {
    #[error("'{token}' is not a number")]
    NotANumber { token: String },
    #[error("a {statement} line needs {needed} numbers, it has {found}")]
    TooFewNumbers { statement: &'static str, needed: usize, found: usize },
    #[error("a face needs at least 3 corners, it has {found}")]
    TooFewCorners { found: usize },
    #[error("face corner '{token}' is not v, v/vt, v//vn or v/vt/vn with whole-number indices")]
    BadCorner { token: String },
    #[error("face {kind} index 0: indices count from 1, or back from -1")]
    ZeroIndex { kind: IndexKind },
    #[error("face {kind} index out of bounds: {index}, and the file has {count} {} lines", kind.statement())]
    PastTheEnd { kind: IndexKind, index: i64, count: u64 },
    #[error(
        "face {kind} index out of bounds: {index} counts back past the {count} {} lines before it",
        kind.statement()
    )]
    BeforeTheStart { kind: IndexKind, index: i64, count: u64 },
}

/// Which list a face corner's index points into.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum IndexKind {
    Vertex,
    Texcoord,
    Normal,
}

impl IndexKind {
    fn statement(self) -> &'static str {
        match self {
            IndexKind::Vertex => "v",
            IndexKind::Texcoord => "vt",
            IndexKind::Normal => "vn",
        }
    }
}

impl std::fmt::Display for IndexKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            IndexKind::Vertex => "vertex",
            IndexKind::Texcoord => "texcoord",
            IndexKind::Normal => "normal",
        })
    }
}

/// Reads an OBJ file's bytes into one mesh of all its objects and groups, on rayon's threads.
pub fn read(bytes: &[u8]) -> Result<ObjMesh, ObjError> {
    let pieces = (bytes.len() / CHUNK_BYTES).max(2 * rayon::current_num_threads());
    let size = bytes.len().div_ceil(pieces).max(MIN_CHUNK_BYTES);
    read_chunks(bytes, &chunks(bytes, size))
}

/// Reads the file in the chunks `chunks`, which split it at line ends.
fn read_chunks(bytes: &[u8], chunks: &[Range<usize>]) -> Result<ObjMesh, ObjError> {
    let counts: Vec<Counts> = chunks.par_iter().map(|r| Counts::of(&bytes[r.clone()])).collect();
    let totals = counts.iter().fold(Counts::default(), |a, b| a.plus(b));
    let before: Vec<Counts> = counts
        .iter()
        .scan(Counts::default(), |sum, c| {
            let start = *sum;
            *sum = sum.plus(c);
            Some(start)
        })
        .collect();
    let parsed: Vec<Result<Chunk, Failure>> = chunks
        .par_iter()
        .zip(counts.par_iter().zip(before.par_iter()))
        .map(|(range, (counts, before))| {
            let mut reader = ChunkReader::new(range.start, *before, totals, counts);
            reader.read(&bytes[range.clone()]).map(|()| reader.chunk)
        })
        .collect();
    let mut read = Vec::with_capacity(parsed.len());
    for chunk in parsed {
        match chunk {
            Ok(chunk) => read.push(chunk),
            Err(Failure { offset, problem }) => return Err(ObjError { line: line_at(bytes, offset), problem }),
        }
    }
    Ok(join(read, bytes))
}

/// The 1-based line that holds byte `offset`.
fn line_at(bytes: &[u8], offset: usize) -> usize {
    memchr::memchr_iter(b'\n', &bytes[..offset.min(bytes.len())]).count() + 1
}

/// The byte ranges of chunks of about `size` bytes (at least 1), each ending after a line end or at the end of
/// the file.
fn chunks(bytes: &[u8], size: usize) -> Vec<Range<usize>> {
    let size = size.max(1);
    let mut ranges = Vec::with_capacity(bytes.len() / size + 1);
    let mut start = 0;
    while start < bytes.len() {
        let mut end = (start + size).min(bytes.len());
        if end < bytes.len() {
            end = memchr::memchr(b'\n', &bytes[end..]).map_or(bytes.len(), |i| end + i + 1);
        }
        ranges.push(start..end);
        start = end;
    }
    ranges
}

/// The statements the reader tells apart.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Statement {
    Position,
    Texcoord,
    Normal,
    Face,
    /// `o` or `g`.
    Name,
    /// `l`, which tobj counts as a face when it splits models.
    Polyline,
    Other,
}

impl Statement {
    fn of(keyword: &[u8]) -> Statement {
        match keyword {
            b"v" => Statement::Position,
            b"vt" => Statement::Texcoord,
            b"vn" => Statement::Normal,
            b"f" => Statement::Face,
            b"o" | b"g" => Statement::Name,
            b"l" => Statement::Polyline,
            _ => Statement::Other,
        }
    }
}

/// The whitespace `str::split_whitespace` splits tobj's lines at, in ASCII.
fn is_space(b: u8) -> bool {
    matches!(b, b' ' | b'\t' | b'\r' | 0x0b | 0x0c)
}

/// The words of the line that starts at a byte of `bytes`: runs of bytes between whitespace, up to the line's
/// `\n` or a word that starts with `#`, which starts a comment. Reading them walks the line once, finding its
/// end on the way.
struct Words<'a> {
    bytes: &'a [u8],
    at: usize,
}

impl<'a> Words<'a> {
    fn new(bytes: &'a [u8], line_start: usize) -> Self {
        Words { bytes, at: line_start }
    }

    /// The offset of the line's `\n`, or the end of `bytes`.
    fn line_end(&self) -> usize {
        let rest = &self.bytes[self.at.min(self.bytes.len())..];
        match rest.first() {
            Some(b'\n') => self.at,
            _ => memchr::memchr(b'\n', rest).map_or(self.bytes.len(), |i| self.at + i),
        }
    }
}

impl<'a> Iterator for Words<'a> {
    type Item = &'a [u8];

    fn next(&mut self) -> Option<&'a [u8]> {
        let bytes = self.bytes;
        let mut at = self.at;
        while at < bytes.len() && is_space(bytes[at]) {
            at += 1;
        }
        self.at = at;
        if at == bytes.len() || bytes[at] == b'\n' || bytes[at] == b'#' {
            return None;
        }
        while at < bytes.len() && bytes[at] != b'\n' && !is_space(bytes[at]) {
            at += 1;
        }
        let word = &bytes[self.at..at];
        self.at = at;
        Some(word)
    }
}

/// How many lines of each kind a chunk holds.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
struct Counts {
    positions: u64,
    texcoords: u64,
    normals: u64,
    faces: u64,
}

impl Counts {
    fn of(bytes: &[u8]) -> Counts {
        let mut c = Counts::default();
        let mut start = 0;
        while start < bytes.len() {
            let mut words = Words::new(bytes, start);
            match words.next().map(Statement::of) {
                Some(Statement::Position) => c.positions += 1,
                Some(Statement::Texcoord) => c.texcoords += 1,
                Some(Statement::Normal) => c.normals += 1,
                Some(Statement::Face) => c.faces += 1,
                _ => {}
            }
            start = words.line_end() + 1;
        }
        c
    }

    fn plus(&self, o: &Counts) -> Counts {
        Counts {
            positions: self.positions + o.positions,
            texcoords: self.texcoords + o.texcoords,
            normals: self.normals + o.normals,
            faces: self.faces + o.faces,
        }
    }
}

/// A line that splits the triangles into objects, at the chunk's triangle count when it was read.
enum Split {
    /// An `o` or `g` line, with the byte range of its name in the file.
    Name(Range<usize>),
    Polyline,
}

/// What one chunk's lines give, its indices already resolved against the whole file.
#[derive(Default)]
struct Chunk {
    positions: Vec<Vec3>,
    texcoords: Vec<Vec2>,
    normals: Vec<Vec3>,
    triangles: Vec<[u32; 3]>,
    triangle_texcoords: Vec<[u32; 3]>,
    triangle_normals: Vec<[u32; 3]>,
    splits: Vec<(usize, Split)>,
}

/// The first problem of a chunk, at its offset in the file.
struct Failure {
    offset: usize,
    problem: ObjProblem,
}

/// A face corner's indices, zero-based, [`NONE`] where absent.
#[derive(Clone, Copy)]
struct Corner {
    v: u32,
    vt: u32,
    vn: u32,
}

/// Reads one chunk, knowing the lines of each kind before it and in the whole file.
struct ChunkReader {
    /// The chunk's first byte in the file.
    offset: usize,
    /// Lines of each kind before the chunk and, as it is read, before the current line.
    before: Counts,
    totals: Counts,
    chunk: Chunk,
}

impl ChunkReader {
    fn new(offset: usize, before: Counts, totals: Counts, own: &Counts) -> Self {
        let chunk = Chunk {
            positions: Vec::with_capacity(own.positions as usize),
            texcoords: Vec::with_capacity(own.texcoords as usize),
            normals: Vec::with_capacity(own.normals as usize),
            triangles: Vec::with_capacity(own.faces as usize),
            ..Chunk::default()
        };
        ChunkReader { offset, before, totals, chunk }
    }

    fn read(&mut self, bytes: &[u8]) -> Result<(), Failure> {
        let mut start = 0;
        while start < bytes.len() {
            let end = self.line(bytes, start).map_err(|problem| Failure { offset: self.offset + start, problem })?;
            start = end + 1;
        }
        Ok(())
    }

    /// Reads the line of `bytes` (the chunk) that starts at `start`, and gives its end.
    fn line(&mut self, bytes: &[u8], start: usize) -> Result<usize, ObjProblem> {
        let mut words = Words::new(bytes, start);
        let Some(keyword) = words.next() else { return Ok(words.line_end()) };
        match Statement::of(keyword) {
            Statement::Position => {
                let [x, y, z] = numbers("v", &mut words, 3)?;
                self.chunk.positions.push(Vec3::new(x, y, z));
                self.before.positions += 1;
            }
            Statement::Texcoord => {
                let [u, v] = numbers("vt", &mut words, 1)?;
                self.chunk.texcoords.push(Vec2::new(u, v));
                self.before.texcoords += 1;
            }
            Statement::Normal => {
                let [x, y, z] = numbers("vn", &mut words, 3)?;
                self.chunk.normals.push(Vec3::new(x, y, z));
                self.before.normals += 1;
            }
            Statement::Face => self.face(&mut words)?,
            Statement::Name => {
                let name = self.offset + words.at..self.offset + words.line_end();
                self.chunk.splits.push((self.chunk.triangles.len(), Split::Name(name)));
            }
            Statement::Polyline => self.chunk.splits.push((self.chunk.triangles.len(), Split::Polyline)),
            Statement::Other => {}
        }
        Ok(words.line_end())
    }

    /// A face's corners, fanned from the first as tobj fans them: (0, 1, 2), (0, 2, 3), …
    fn face(&mut self, words: &mut Words) -> Result<(), ObjProblem> {
        let mut found = 0;
        let mut first = None;
        let mut previous = None;
        for word in words {
            let c = self.corner(word)?;
            found += 1;
            match (first, previous) {
                (None, _) => first = Some(c),
                (Some(a), Some(b)) => {
                    self.triangle([a, b, c]);
                    previous = Some(c);
                }
                (Some(_), None) => previous = Some(c),
            }
        }
        if found < 3 {
            return Err(ObjProblem::TooFewCorners { found });
        }
        Ok(())
    }

    fn triangle(&mut self, [a, b, c]: [Corner; 3]) {
        let chunk = &mut self.chunk;
        let before = chunk.triangles.len();
        chunk.triangles.push([a.v, b.v, c.v]);
        push_optional(&mut chunk.triangle_texcoords, before, [a.vt, b.vt, c.vt]);
        push_optional(&mut chunk.triangle_normals, before, [a.vn, b.vn, c.vn]);
    }

    fn corner(&self, word: &[u8]) -> Result<Corner, ObjProblem> {
        let bad = || ObjProblem::BadCorner { token: shown(word) };
        let mut parts = word.split(|&b| b == b'/');
        let v = parts.next().unwrap_or_default();
        let vt = parts.next().unwrap_or_default();
        let vn = parts.next().unwrap_or_default();
        // tobj lets further parts be empty ("1/2/3/").
        if v.is_empty() || parts.any(|p| !p.is_empty()) {
            return Err(bad());
        }
        let index = |part: &[u8], kind: IndexKind, before: u64, total: u64| -> Result<u32, ObjProblem> {
            if part.is_empty() {
                return Ok(NONE);
            }
            let i = integer(part).ok_or_else(bad)?;
            if i == 0 {
                return Err(ObjProblem::ZeroIndex { kind });
            }
            if total == 0 && kind != IndexKind::Vertex {
                return Ok(NONE);
            }
            resolve(i, kind, before, total)
        };
        let (b, t) = (&self.before, &self.totals);
        Ok(Corner {
            v: index(v, IndexKind::Vertex, b.positions, t.positions)?,
            vt: index(vt, IndexKind::Texcoord, b.texcoords, t.texcoords)?,
            vn: index(vn, IndexKind::Normal, b.normals, t.normals)?,
        })
    }
}

/// Pushes a triangle's optional indices, keeping `list` empty until some corner gives one and then as long as
/// the triangles before it (`before`).
fn push_optional(list: &mut Vec<[u32; 3]>, before: usize, t: [u32; 3]) {
    if list.is_empty() {
        if t == [NONE; 3] {
            return;
        }
        list.resize(before, [NONE; 3]);
    }
    list.push(t);
}

/// The zero-based index that the 1-based or negative index `i` names among `total` lines, `before` of them
/// read before its face.
fn resolve(i: i64, kind: IndexKind, before: u64, total: u64) -> Result<u32, ObjProblem> {
    let zero_based = if i > 0 { i - 1 } else { before as i64 + i };
    if zero_based < 0 {
        return Err(ObjProblem::BeforeTheStart { kind, index: i, count: before });
    }
    if zero_based as u64 >= total || zero_based >= NONE as i64 {
        return Err(ObjProblem::PastTheEnd { kind, index: i, count: total });
    }
    Ok(zero_based as u32)
}

/// An optionally signed decimal integer, as `isize::from_str` takes it; one of more than 18 digits saturates,
/// which makes it an index out of bounds.
fn integer(word: &[u8]) -> Option<i64> {
    let (negative, digits) = match word.first() {
        Some(b'-') => (true, &word[1..]),
        Some(b'+') => (false, &word[1..]),
        _ => (false, word),
    };
    if digits.is_empty() {
        return None;
    }
    let mut n: i64 = 0;
    for &d in digits {
        if !d.is_ascii_digit() {
            return None;
        }
        n = n.wrapping_mul(10).wrapping_add((d - b'0') as i64);
    }
    // Up to 18 digits after the leading zeros cannot overflow.
    if digits.iter().position(|&d| d != b'0').is_some_and(|first| digits.len() - first > 18) {
        n = i64::MAX;
    }
    Some(if negative { -n } else { n })
}

/// The first `N` numbers of a statement's words, of which it needs `needed` (those it may leave out are 0);
/// further words are not read.
fn numbers<const N: usize>(statement: &'static str, words: &mut Words, needed: usize) -> Result<[f32; N], ObjProblem> {
    let mut out = [0.0; N];
    for (found, x) in out.iter_mut().enumerate() {
        let Some(word) = words.next() else {
            if found < needed {
                return Err(ObjProblem::TooFewNumbers { statement, needed, found });
            }
            break;
        };
        *x = number(word).ok_or_else(|| ObjProblem::NotANumber { token: shown(word) })?;
    }
    Ok(out)
}

/// A number as tobj reads it (`f32::from_str`, which rounds correctly and takes "inf" and "NaN").
fn number(word: &[u8]) -> Option<f32> {
    std::str::from_utf8(word).ok()?.parse().ok()
}

/// A word as an error shows it: its first 40 bytes, lossily decoded.
fn shown(word: &[u8]) -> String {
    let mut s = String::from_utf8_lossy(&word[..word.len().min(40)]).into_owned();
    if word.len() > 40 {
        s.push('…');
    }
    s
}

/// The chunks' lists joined in order, the vertices' beside the triangles', and the objects their splits make.
fn join(chunks: Vec<Chunk>, bytes: &[u8]) -> ObjMesh {
    let n = chunks.len();
    let (mut positions, mut texcoords, mut normals) =
        (Vec::with_capacity(n), Vec::with_capacity(n), Vec::with_capacity(n));
    let (mut triangles, mut triangle_texcoords, mut triangle_normals) =
        (Vec::with_capacity(n), Vec::with_capacity(n), Vec::with_capacity(n));
    let mut objects = Objects::default();
    let mut before = 0;
    for chunk in chunks {
        for (at, split) in chunk.splits {
            objects.split(before + at, split, bytes);
        }
        before += chunk.triangles.len();
        positions.push(chunk.positions);
        texcoords.push(chunk.texcoords);
        normals.push(chunk.normals);
        triangle_texcoords.push((chunk.triangle_texcoords, chunk.triangles.len()));
        triangle_normals.push((chunk.triangle_normals, chunk.triangles.len()));
        triangles.push(chunk.triangles);
    }
    let ((positions, texcoords, normals), (triangles, triangle_texcoords, triangle_normals)) = rayon::join(
        || (concat(positions), concat(texcoords), concat(normals)),
        || (concat(triangles), concat_optional(triangle_texcoords), concat_optional(triangle_normals)),
    );
    ObjMesh {
        positions,
        texcoords,
        normals,
        triangles,
        triangle_texcoords,
        triangle_normals,
        objects: objects.finish(before, bytes),
    }
}

/// The lists one after the other, each let go once copied.
fn concat<T: Copy>(mut lists: Vec<Vec<T>>) -> Vec<T> {
    if lists.len() == 1 {
        return lists.pop().unwrap_or_default();
    }
    let mut out = Vec::with_capacity(lists.iter().map(Vec::len).sum());
    for list in lists {
        out.extend_from_slice(&list);
    }
    out
}

/// Chunks' optional corner indices, with the chunks' triangle counts: joined, a chunk whose corners name none
/// given [`NONE`]s, or empty when no chunk's corners name one.
fn concat_optional(lists: Vec<(Vec<[u32; 3]>, usize)>) -> Vec<[u32; 3]> {
    if lists.iter().all(|(list, _)| list.is_empty()) {
        return Vec::new();
    }
    let filled = lists.into_iter().map(|(list, count)| if list.is_empty() { vec![[NONE; 3]; count] } else { list });
    concat(filled.collect())
}

/// The objects as tobj makes its models: an `o` or `g` line ends the current one when it has faces (an `l` line
/// counts as one), and names the next.
#[derive(Default)]
struct Objects {
    done: Vec<ObjObject>,
    /// The byte range of the current object's name, which is made a string only for an object with triangles.
    name: Option<Range<usize>>,
    start: usize,
    polyline: bool,
}

/// tobj's name for a model before any `o` or `g` line, or after one without a name.
const UNNAMED: &str = "unnamed_object";

impl Objects {
    fn split(&mut self, at: usize, split: Split, bytes: &[u8]) {
        match split {
            Split::Polyline => self.polyline = true,
            Split::Name(range) => {
                if at > self.start || self.polyline {
                    self.end(at, bytes);
                }
                self.name = Some(range);
            }
        }
    }

    fn end(&mut self, at: usize, bytes: &[u8]) {
        if at > self.start {
            let name = self.name.clone().map(|r| String::from_utf8_lossy(&bytes[r]).trim().to_string());
            let name = name.filter(|n| !n.is_empty()).unwrap_or_else(|| UNNAMED.into());
            self.done.push(ObjObject { name, triangles: self.start..at });
        }
        self.start = at;
        self.polyline = false;
    }

    fn finish(mut self, triangles: usize, bytes: &[u8]) -> Vec<ObjObject> {
        self.end(triangles, bytes);
        self.done
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use rand_core::{RngCore, SeedableRng};
    use rand_pcg::Pcg32;

    fn mesh(text: &str) -> ObjMesh {
        read(text.as_bytes()).unwrap_or_else(|e| panic!("{e}\n{text}"))
    }

    fn error(text: &str) -> ObjError {
        read(text.as_bytes()).expect_err(text)
    }

    const SQUARE: &str = "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\n";

    #[test]
    fn negative_indices_count_back_from_the_vertices_read_so_far() {
        let m = mesh("v 0 0 0\nv 1 0 0\nv 1 1 0\nf -3 -2 -1\nv 0 1 0\nf -4 -2 -1\n");
        assert_eq!(m.triangles, vec![[0, 1, 2], [0, 2, 3]]);
        let m = mesh("v 0 0 0\nv 1 0 0\nv 1 1 0\nvt 0 0\nvt 1 0\nvn 0 0 1\nf -3/-2/-1 -2/-1/-1 -1/-1/-1\n");
        assert_eq!(m.triangle_texcoords, vec![[0, 1, 1]]);
        assert_eq!(m.triangle_normals, vec![[0, 0, 0]]);
    }

    #[test]
    fn a_pentagon_is_fanned_as_tobj_fans_it() {
        let text = "v 0 0 0\nv 1 0 0\nv 2 1 0\nv 1 2 0\nv 0 1 0\nf 1 2 3 4 5\nf 5 4 3 2\n";
        assert_eq!(mesh(text).triangles, vec![[0, 1, 2], [0, 2, 3], [0, 3, 4], [4, 3, 2], [4, 2, 1]]);
        same_as_tobj(text);
    }

    #[test]
    fn an_index_past_the_vertices_is_an_error_naming_its_line() {
        let e = error(&format!("{SQUARE}\nf 1 2 3\nf 1 2 5\n"));
        assert_eq!(e.line, 7);
        assert_eq!(e.problem, ObjProblem::PastTheEnd { kind: IndexKind::Vertex, index: 5, count: 4 });
        assert!(e.to_string().contains("face vertex index out of bounds"), "{e}");
        let e = error(&format!("{SQUARE}f -1 -2 -5\n"));
        assert_eq!(e.problem, ObjProblem::BeforeTheStart { kind: IndexKind::Vertex, index: -5, count: 4 });
        let e = error(&format!("{SQUARE}vt 0 0\nf 1/1 2/1 3/2\n"));
        assert_eq!((e.line, e.problem.to_string().contains("face texcoord index out of bounds")), (6, true), "{e}");
        let e = error(&format!("{SQUARE}vn 0 0 1\nf 1//1 2//1 3//-2\n"));
        assert_eq!((e.line, e.problem.to_string().contains("face normal index out of bounds")), (6, true), "{e}");
        let e = error(&format!("{SQUARE}f 1 2 99999999999999999999999\n"));
        assert!(matches!(e.problem, ObjProblem::PastTheEnd { .. }), "{e}");
        assert_eq!(mesh(&format!("{SQUARE}f 1 2 00000000000000000000003\n")).triangles, vec![[0, 1, 2]]);
    }

    #[test]
    fn an_index_of_zero_is_an_error() {
        let e = error(&format!("{SQUARE}f 0 1 2\n"));
        assert_eq!((e.line, e.problem), (5, ObjProblem::ZeroIndex { kind: IndexKind::Vertex }));
        let e = error(&format!("{SQUARE}vn 0 0 1\nf 1//1 2//0 3//1\n"));
        assert_eq!((e.line, e.problem), (6, ObjProblem::ZeroIndex { kind: IndexKind::Normal }));
    }

    #[test]
    fn a_face_with_fewer_than_three_corners_is_an_error() {
        for (face, found) in [("f", 0), ("f 1", 1), ("f 1 2 # 3", 2)] {
            let e = error(&format!("{SQUARE}{face}\n"));
            assert_eq!((e.line, e.problem), (5, ObjProblem::TooFewCorners { found }));
        }
    }

    #[test]
    fn a_malformed_number_is_an_error_naming_its_line() {
        let e = error("v 0 0 0\nv 1 0x 0\n");
        assert_eq!((e.line, e.problem), (2, ObjProblem::NotANumber { token: "0x".into() }));
        let e = error("v 0 0 0\r\n\r\nvn 1 0 1,5\r\n");
        assert_eq!((e.line, e.problem), (3, ObjProblem::NotANumber { token: "1,5".into() }));
        assert_eq!(error("vt 0.5 1.2.3\n").problem, ObjProblem::NotANumber { token: "1.2.3".into() });
        assert_eq!(error("v 1 2 3#c\n").problem, ObjProblem::NotANumber { token: "3#c".into() });
    }

    #[test]
    fn a_statement_with_too_few_coordinates_is_an_error() {
        let few = |statement, needed, found| ObjProblem::TooFewNumbers { statement, needed, found };
        assert_eq!(error("v 1 2\n").problem, few("v", 3, 2));
        assert_eq!(error("v 1 2 # 3\n").problem, few("v", 3, 2));
        assert_eq!(error("vn\n").problem, few("vn", 3, 0));
        assert_eq!(error("vt\n").problem, few("vt", 1, 0));
    }

    #[test]
    fn a_corner_that_is_not_an_index_is_an_error() {
        for corner in ["a", "1.5", "1/x", "1//-", "/1", "//1", "1/2/3/4", "--1", "+", "1 /2"] {
            let e = error(&format!("{SQUARE}vt 0 0\nvn 0 0 1\nf 1 2 {corner}\n"));
            assert_eq!(e.line, 7, "{corner}: {e}");
            assert!(matches!(e.problem, ObjProblem::BadCorner { .. }), "{corner}: {e}");
        }
    }

    #[test]
    fn corners_name_texture_coordinates_and_normals_in_every_form() {
        let text =
            format!("{SQUARE}vt 0 0\nvt 1 0\nvn 0 0 1\nf 1 2 3\nf 1/1 2/2 3/1\nf 1//1 2//1 3//1\nf 1/2/1 2/1/1 3/2/\n");
        let m = mesh(&text);
        assert_eq!(m.triangles, vec![[0, 1, 2]; 4]);
        assert_eq!(m.triangle_texcoords, vec![[NONE; 3], [0, 1, 0], [NONE; 3], [1, 0, 1]]);
        assert_eq!(m.triangle_normals, vec![[NONE; 3], [NONE; 3], [0, 0, 0], [0, 0, NONE]]);
        assert_eq!(m.texcoords, vec![Vec2::ZERO, Vec2::X]);
        assert_eq!(m.normals, vec![Vec3::Z]);
        same_as_tobj(&text);
    }

    #[test]
    fn a_file_whose_corners_name_no_texture_coordinates_or_normals_has_no_lists_of_them() {
        let m = mesh(&format!("{SQUARE}vt 0 0\nvn 0 0 1\nf 1 2 3\n"));
        assert!(m.triangle_texcoords.is_empty() && m.triangle_normals.is_empty());
    }

    #[test]
    fn texture_and_normal_indices_of_a_file_without_vt_or_vn_lines_are_not_read() {
        let m = mesh(&format!("{SQUARE}f 1/7/9 2/7/9 3/7/9\n"));
        assert!(m.triangle_texcoords.is_empty() && m.triangle_normals.is_empty());
        same_as_tobj(&format!("{SQUARE}f 1/7/9 2/7/9 3/7/9\n"));
    }

    #[test]
    fn extra_numbers_after_a_statement_are_ignored_and_a_missing_v_is_zero() {
        let m = mesh("v 1 2 3 2\nv 4 5 6 0.1 0.2 0.3\nvt 0.25\nvt 0.5 0.75 1\nvn 0 0 1 1\n");
        assert_eq!(m.positions, vec![Vec3::new(1.0, 2.0, 3.0), Vec3::new(4.0, 5.0, 6.0)]);
        assert_eq!(m.texcoords, vec![Vec2::new(0.25, 0.0), Vec2::new(0.5, 0.75)]);
        assert_eq!(m.normals, vec![Vec3::Z]);
    }

    #[test]
    fn comments_blank_lines_crlf_tabs_and_other_statements_are_skipped() {
        let text = "# a square\r\n\r\nmtllib a b.mtl\r\n\tv 0 0 0 # first\r\nv\t1 0 0\r\nv 1 1 0\r\nv 0 1 0\r\n\
                    usemtl\r\ns off\r\np 1\r\nl 1 2\r\n#f 1 2 3\r\ncurv 1 2\r\nvp 0.5\r\n  \t\r\n\
                    f 1 2 3 4 # quad\r\nf 1 3 4";
        let m = mesh(text);
        assert_eq!(m.positions.len(), 4);
        assert_eq!(m.triangles, vec![[0, 1, 2], [0, 2, 3], [0, 2, 3]]);
    }

    #[test]
    fn o_and_g_lines_split_the_triangles_where_tobj_splits_its_models() {
        let text = format!(
            "{SQUARE}f 1 2 3\ng  wall  \ng floor\nf 1 2 3\nf 1 3 4\no\nl 1 2\no lid # top\nf 1 2 3\ng\ng x\nl 1 3\n"
        );
        let names: Vec<(String, Range<usize>)> =
            mesh(&text).objects.into_iter().map(|o| (o.name, o.triangles)).collect();
        let expected = [("unnamed_object", 0..1), ("floor", 1..3), ("lid # top", 3..4)];
        assert_eq!(names, expected.map(|(n, r)| (n.to_string(), r)));
        same_as_tobj(&text);
    }

    #[test]
    fn the_chunks_a_file_is_read_in_do_not_change_what_it_gives() {
        let mut rng = Pcg32::seed_from_u64(11);
        let mut text = String::new();
        for k in 0..3000 {
            text.push_str(&format!("v {k} {} 0\nvt 0.{k} 1\nvn 0 0 1\n", k % 7));
            if k >= 3 {
                text.push_str(&format!("f -1/-1/-1 -2/-2/-1 -3/{}/{} 1\n", k - 1, k));
            }
            if k % 500 == 0 {
                text.push_str(&format!("o part{k}\n"));
            }
        }
        let bytes = text.as_bytes();
        let whole = read_chunks(bytes, &chunks(bytes, bytes.len())).unwrap();
        assert_eq!(whole.triangles.len(), 2997 * 2);
        assert_eq!(whole.objects.len(), 6);
        for size in [1, 17, 1000, 1 << 16] {
            assert_eq!(read_chunks(bytes, &chunks(bytes, size)).as_ref(), Ok(&whole), "chunks of {size}");
        }
        assert_eq!(read(bytes).as_ref(), Ok(&whole));
        let bad = format!("{text}f 1 2 3\nf 1 2 {}\n", 3001 + rng.next_u32() % 100);
        let lines = bad.lines().count();
        for size in [1, 17, 1000, 1 << 16] {
            let e = read_chunks(bad.as_bytes(), &chunks(bad.as_bytes(), size)).unwrap_err();
            assert_eq!(e.line, lines, "chunks of {size}: {e}");
        }
    }

    #[test]
    fn random_files_give_the_triangles_tobj_gives() {
        let mut rng = Pcg32::seed_from_u64(7);
        for _ in 0..400 {
            let text = random_obj(&mut rng);
            same_as_tobj(&text);
            let bytes = text.as_bytes();
            let size = 1 + (rng.next_u32() % 64) as usize;
            assert_eq!(read_chunks(bytes, &chunks(bytes, size)), read(bytes), "chunks of {size}:\n{text}");
        }
    }

    #[test]
    fn random_and_mangled_bytes_give_a_mesh_or_an_error() {
        let mut rng = Pcg32::seed_from_u64(5);
        const ALPHABET: &[u8] = b"vtnfoglp0123456789.-+/#eE \t\r\n\n\n\x0b\xff";
        for round in 0..3000 {
            let bytes: Vec<u8> = if round % 2 == 0 {
                let n = rng.next_u32() % 300;
                (0..n).map(|_| ALPHABET[(rng.next_u32() as usize) % ALPHABET.len()]).collect()
            } else {
                let mut b = random_obj(&mut rng).into_bytes();
                for _ in 0..1 + rng.next_u32() % 4 {
                    let at = rng.next_u32() as usize % (b.len() + 1);
                    let byte =
                        if rng.next_u32() % 2 == 0 { rng.next_u32() as u8 } else { ALPHABET[at % ALPHABET.len()] };
                    match rng.next_u32() % 3 {
                        0 if at < b.len() => b[at] = byte,
                        1 if at < b.len() => drop(b.remove(at)),
                        _ => b.insert(at, byte),
                    }
                }
                b
            };
            let whole = read(&bytes);
            if let Err(e) = &whole {
                assert!(e.line >= 1 && e.line <= bytes.split(|&b| b == b'\n').count(), "{e}");
            }
            let size = 1 + (rng.next_u32() % 32) as usize;
            assert_eq!(read_chunks(&bytes, &chunks(&bytes, size)), whole);
        }
    }

    /// Checks that tobj, as the scene readers called it, and `read` give the same objects, with the same
    /// triangles' positions and, where tobj gives them for every vertex, normals and texture coordinates.
    fn same_as_tobj(text: &str) {
        let options =
            tobj::LoadOptions { triangulate: true, single_index: true, ignore_points: true, ignore_lines: true };
        let (models, _) = tobj::load_obj_buf(&mut text.as_bytes(), &options, |_| Err(tobj::LoadError::OpenFileFailed))
            .unwrap_or_else(|e| panic!("tobj: {e}\n{text}"));
        let ours = mesh(text);
        let models: Vec<&tobj::Model> = models.iter().filter(|m| !m.mesh.indices.is_empty()).collect();
        assert_eq!(models.len(), ours.objects.len(), "{text}");
        for (model, object) in models.iter().zip(&ours.objects) {
            let m = &model.mesh;
            assert_eq!((&model.name, m.indices.len() / 3), (&object.name, object.triangles.len()), "{text}");
            let vertices = m.positions.len() / 3;
            let theirs = |list: &[f32], n: usize| match list.len() {
                0 => Coverage::None,
                l if l == n * vertices => Coverage::All,
                _ => Coverage::Partial,
            };
            let normals = coverage(&ours.triangle_normals, object.triangles.clone());
            let texcoords = coverage(&ours.triangle_texcoords, object.triangles.clone());
            assert_eq!(theirs(&m.normals, 3), normals, "normals of {}:\n{text}", model.name);
            assert_eq!(theirs(&m.texcoords, 2), texcoords, "texcoords of {}:\n{text}", model.name);
            for (k, corners) in m.indices.chunks_exact(3).enumerate() {
                let t = object.triangles.start + k;
                for (c, &i) in corners.iter().enumerate() {
                    let i = i as usize;
                    let p = Vec3::from_slice(&m.positions[3 * i..]);
                    assert_eq!(p, ours.positions[ours.triangles[t][c] as usize], "triangle {t}:\n{text}");
                    if normals == Coverage::All {
                        let n = Vec3::from_slice(&m.normals[3 * i..]);
                        assert_eq!(n, ours.normals[ours.triangle_normals[t][c] as usize], "triangle {t}:\n{text}");
                    }
                    if texcoords == Coverage::All {
                        let uv = Vec2::from_slice(&m.texcoords[2 * i..]);
                        assert_eq!(uv, ours.texcoords[ours.triangle_texcoords[t][c] as usize], "triangle {t}:\n{text}");
                    }
                }
            }
        }
    }

    /// A random OBJ text that tobj reads: positions, texture coordinates and normals in the number forms Rust
    /// reads, faces of 3 to 7 corners in every corner form with 1-based and negative indices to lines already
    /// read, objects and groups, polylines, points, other statements, comments where tobj skips them, CRLF line
    /// ends, tabs and runs of spaces.
    pub(crate) fn random_obj(rng: &mut Pcg32) -> String {
        let mut below = |n: u32| rng.next_u32() % n;
        let crlf = below(3);
        let colors = below(6) == 0;
        // 0: corners give positions alone; 1: every form; 2: one form for the file; 3: one form per object.
        let forms = below(4);
        let mut file_form = below(4);
        let mut out = String::new();
        let (mut v, mut vt, mut vn) = (0u32, 0u32, 0u32);
        let number = |below: &mut dyn FnMut(u32) -> u32| -> String {
            let x = below(20001) as f32 / 1000.0 - 10.0;
            match below(6) {
                0 => format!("{}", below(10) as i32 - 5),
                1 => format!("{x:e}"),
                2 => format!("{x:.3}").replace("0.", "."),
                3 => format!("+{}", x.abs()),
                4 => format!("{}.", below(100)),
                _ => format!("{x}"),
            }
        };
        for _ in 0..10 + below(60) {
            let gap = [" ", "\t", "  ", " \t "][below(4) as usize];
            let mut line = String::new();
            let mut named = false;
            match below(20) {
                0..=4 => {
                    let xyz: Vec<String> = (0..3).map(|_| number(&mut below)).collect();
                    line = format!("v{gap}{}", xyz.join(gap));
                    if colors {
                        line.push_str(" 0.5 0.25 1");
                    }
                    v += 1;
                }
                5 | 6 => {
                    line = format!("vt {} {}", number(&mut below), number(&mut below));
                    if below(3) == 0 {
                        line.push_str(" 0");
                    }
                    if below(4) == 0 {
                        line.push_str(" # w");
                    }
                    vt += 1;
                }
                7 | 8 => {
                    line = format!("vn {} {}{gap}{}", number(&mut below), number(&mut below), number(&mut below));
                    if below(4) == 0 {
                        line.push_str("\t#n");
                    }
                    vn += 1;
                }
                9..=14 if v > 0 => {
                    line.push('f');
                    let corners = 3 + [0, 0, 0, 1, 1, 2, 3, 4][below(8) as usize];
                    let face_form = below(4);
                    for _ in 0..corners {
                        let form = match forms {
                            0 => 0,
                            1 => below(4),
                            2 => file_form,
                            _ => face_form.min(file_form),
                        };
                        let index = |count: u32, below: &mut dyn FnMut(u32) -> u32| {
                            let i = 1 + below(count);
                            if below(3) == 0 {
                                format!("{}", i as i64 - count as i64 - 1)
                            } else {
                                format!("{i}")
                            }
                        };
                        let p = index(v, &mut below);
                        let t = if vt > 0 { index(vt, &mut below) } else { String::new() };
                        let n = if vn > 0 { index(vn, &mut below) } else { String::new() };
                        let corner = match form {
                            1 if vt > 0 => format!("{p}/{t}"),
                            2 if vn > 0 => format!("{p}//{n}"),
                            3 if vt > 0 && vn > 0 => format!("{p}/{t}/{n}"),
                            _ => p,
                        };
                        line.push_str(gap);
                        line.push_str(&corner);
                    }
                }
                15 => {
                    let name = ["", "wall", "a b", "x # y", "\tfloor"][below(5) as usize];
                    line = format!("{} {name}", ["o", "g"][below(2) as usize]);
                    file_form = below(4);
                    // tobj names a model after all but the first character of its line.
                    named = true;
                }
                16 if v > 1 => line = format!("l {} {}", 1 + below(v), 1 + below(v)),
                17 => {
                    line = ["# comment", "", "s 1", "s off", "usemtl red", "mtllib x.mtl", "p 1", "vp 1 2", "\t"]
                        [below(9) as usize]
                        .into()
                }
                _ => {}
            }
            if below(8) == 0 && !named {
                line.insert_str(0, " \t");
            }
            if below(8) == 0 {
                line.push(' ');
            }
            out.push_str(&line);
            out.push_str(if crlf == 0 || (crlf == 1 && below(2) == 0) { "\r\n" } else { "\n" });
        }
        out
    }
}
