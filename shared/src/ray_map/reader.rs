//! Reading a map: its stream files, their headers, and their portions one at a time. A stream that ends inside
//! a portion (a killed run) reads up to its last whole portion and says how many bytes it left; a portion that
//! is damaged is an error that names the file and the byte. A stream file is memory-mapped, so that its portions
//! are decompressed straight from the page cache by whichever thread tests them; a stream that cannot be mapped
//! (a pipe, a special file, a file system without mappings) is read portion by portion instead.

use super::format::{
    path_views, MapHeader, PathViews, PortionHeader, MAGIC, MAX_BLOCK_BYTES, PORTION_HEADER_BYTES, VERSION,
};
use super::path::RecordedPath;
use super::RayMapError;
use memmap2::Mmap;
use std::cell::RefCell;
use std::fs::File;
use std::io::{ErrorKind, Read};
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// A portion's compressed frame: a range of its stream's mapping, or bytes read into a buffer of its own.
#[derive(Clone, Debug)]
pub enum Frame {
    Mapped { map: Arc<Mmap>, start: usize, end: usize },
    Read(Vec<u8>),
}

impl Frame {
    /// The frame's bytes.
    pub fn bytes(&self) -> &[u8] {
        match self {
            Frame::Mapped { map, start, end } => &map[*start..*end],
            Frame::Read(bytes) => bytes,
        }
    }

    /// The frame's length in bytes.
    pub fn len(&self) -> usize {
        self.bytes().len()
    }

    /// True for a frame of no bytes.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

/// A portion as it lies in the file, not yet decompressed (decompression is the part worth parallelising).
#[derive(Clone, Debug)]
pub struct RawPortion {
    pub header: PortionHeader,
    pub frame: Frame,
    /// The stream file and the byte the portion starts at, for errors.
    pub file: PathBuf,
    pub offset: u64,
}

/// A thread's decompressor and raw buffer, reused from portion to portion so that reading a portion allocates
/// nothing once the thread has read one.
struct Scratch {
    decompressor: zstd::bulk::Decompressor<'static>,
    raw: Vec<u8>,
}

/// A raw buffer above this is not kept for the next portion (the writer's portions are 1 MiB).
const KEPT_RAW_BYTES: usize = 16 << 20;

thread_local! {
    static SCRATCH: RefCell<Option<Scratch>> = const { RefCell::new(None) };
}

impl RawPortion {
    /// Decompresses and decodes the portion's paths.
    pub fn decode(&self) -> Result<Vec<RecordedPath>, RayMapError> {
        self.with_paths(|views| views.map(|v| v.map(|v| v.to_path())).collect())
    }

    /// Decompresses the portion into this thread's reusable buffer and hands `f` its paths, read in place. The
    /// views' error items and `f`'s error say what is wrong with the portion, and become a `Corrupt` error
    /// naming its file and byte.
    pub fn with_paths<R>(&self, f: impl FnOnce(PathViews<'_>) -> Result<R, String>) -> Result<R, RayMapError> {
        let corrupt = |reason: String| RayMapError::Corrupt {
            path: self.file.display().to_string(),
            offset: self.offset,
            reason,
        };
        // Taken out of the cell rather than borrowed, so that `f` may read another portion.
        let mut scratch = match SCRATCH.with(|s| s.borrow_mut().take()) {
            Some(s) => s,
            None => Scratch {
                decompressor: zstd::bulk::Decompressor::new()
                    .map_err(|e| corrupt(format!("no zstd decompressor could be made ({e})")))?,
                raw: Vec::new(),
            },
        };
        let want = self.header.raw as usize;
        scratch.raw.clear();
        scratch.raw.reserve(want);
        let result = match scratch.decompressor.decompress_to_buffer(self.frame.bytes(), &mut scratch.raw) {
            Err(e) => Err(corrupt(format!("its compressed data does not decompress ({e})"))),
            Ok(n) if n != want => Err(corrupt(format!("it holds {n} bytes, its header says {want}"))),
            Ok(_) => f(path_views(&scratch.raw, self.header.paths as usize)).map_err(corrupt),
        };
        if scratch.raw.capacity() > KEPT_RAW_BYTES {
            scratch.raw = Vec::new();
        }
        SCRATCH.with(|s| *s.borrow_mut() = Some(scratch));
        result
    }

    /// The buffer a read frame lies in, for the next portion read from an unmapped stream; None for a mapped one.
    pub fn into_buffer(self) -> Option<Vec<u8>> {
        match self.frame {
            Frame::Read(bytes) => Some(bytes),
            Frame::Mapped { .. } => None,
        }
    }
}

/// Where a stream's portions come from.
enum Body {
    Mapped(Arc<Mmap>),
    /// Unbuffered: portions are read whole, most of a MiB each, and a buffer would only copy them twice.
    Read(File),
}

/// One stream file, read portion by portion.
pub struct StreamReader {
    path: PathBuf,
    body: Body,
    header: MapHeader,
    offset: u64,
    length: u64,
    truncated: Option<u64>,
}

impl StreamReader {
    /// Opens a stream and reads its header; a file of another format or version is refused here. A regular file
    /// is mapped; anything else, or a file whose mapping fails, is read.
    pub fn open(path: &Path) -> Result<Self, RayMapError> {
        let name = path.display().to_string();
        let io = |source| RayMapError::Io { path: name.clone(), source };
        let mut file = File::open(path).map_err(io)?;
        let metadata = file.metadata().map_err(io)?;
        // A pipe's length is unknown: its reads say where it ends.
        let regular = metadata.is_file();
        let length = metadata.len();
        let mut start = [0u8; 16];
        if regular && length < 16 {
            return Err(RayMapError::NotAMap(name));
        }
        file.read_exact(&mut start).map_err(|e| match e.kind() {
            ErrorKind::UnexpectedEof => RayMapError::NotAMap(name.clone()),
            _ => io(e),
        })?;
        if &start[..8] != MAGIC {
            return Err(RayMapError::NotAMap(name));
        }
        let version = u32::from_le_bytes(start[8..12].try_into().expect("4 bytes"));
        if version != VERSION {
            return Err(RayMapError::Version { path: name, found: version, supported: VERSION });
        }
        let json_len = u32::from_le_bytes(start[12..16].try_into().expect("4 bytes")) as u64;
        let cut_header =
            || RayMapError::Header { path: name.clone(), reason: "the file ends inside its header".into() };
        if json_len > MAX_BLOCK_BYTES as u64 || (regular && 16 + json_len > length) {
            return Err(cut_header());
        }
        let mut json = vec![0u8; json_len as usize];
        file.read_exact(&mut json).map_err(|e| match e.kind() {
            ErrorKind::UnexpectedEof => cut_header(),
            _ => io(e),
        })?;
        let header: MapHeader = serde_json::from_slice(&json)
            .map_err(|e| RayMapError::Header { path: name.clone(), reason: e.to_string() })?;
        let body = if regular {
            // SAFETY: the mapping is only read, and only below the length the file had when it was opened. The
            // recorder only appends to a stream, so a map still being written stays valid; a stream cut shorter
            // while it is read (a render started again into the same folder) would end the process with SIGBUS
            // where a read would have been an error.
            match unsafe { Mmap::map(&file) } {
                Ok(map) => Body::Mapped(Arc::new(map)),
                Err(_) => Body::Read(file),
            }
        } else {
            Body::Read(file)
        };
        Ok(StreamReader { path: path.to_path_buf(), body, header, offset: 16 + json_len, length, truncated: None })
    }

    /// True when the stream is read through a memory mapping, false when it is read portion by portion.
    pub fn is_mapped(&self) -> bool {
        matches!(self.body, Body::Mapped(_))
    }

    /// The stream file.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The stream's header.
    pub fn header(&self) -> &MapHeader {
        &self.header
    }

    /// Bytes after the last whole portion, once the reader has reached a stream cut inside a portion.
    pub fn truncated_bytes(&self) -> Option<u64> {
        self.truncated
    }

    /// The stream's size in bytes when it was opened (0 for a pipe, whose size is unknown).
    pub fn len(&self) -> u64 {
        self.length
    }

    /// True for a stream of unknown size (a pipe): `open` refuses a regular file of no bytes.
    pub fn is_empty(&self) -> bool {
        self.length == 0
    }

    /// The next whole portion, None at the end (or at a cut, which `truncated_bytes` then reports).
    pub fn next_portion(&mut self) -> Result<Option<RawPortion>, RayMapError> {
        self.next_portion_into(&mut Vec::new())
    }

    /// `next_portion`, reading an unmapped stream's frame into `buffer`'s allocation (taken from it: an earlier
    /// portion's, from `RawPortion::into_buffer`, so that streaming a map does not allocate per portion). A
    /// mapped stream's frame is a range of its mapping, and `buffer` is left as it is.
    pub fn next_portion_into(&mut self, buffer: &mut Vec<u8>) -> Result<Option<RawPortion>, RayMapError> {
        let offset = self.offset;
        let corrupt = |reason| RayMapError::Corrupt { path: self.path.display().to_string(), offset, reason };
        let io = |source| RayMapError::Io { path: self.path.display().to_string(), source };
        let (header, frame) = match &mut self.body {
            Body::Mapped(map) => {
                let left = map.len() - offset as usize;
                if left == 0 {
                    return Ok(None);
                }
                if left < PORTION_HEADER_BYTES {
                    self.truncated = Some(left as u64);
                    return Ok(None);
                }
                let at = offset as usize;
                let head = map[at..at + PORTION_HEADER_BYTES].try_into().expect("a portion header's bytes");
                let header = PortionHeader::from_bytes(head).map_err(corrupt)?;
                let end = at + PORTION_HEADER_BYTES + header.compressed as usize;
                if end > map.len() {
                    self.truncated = Some(left as u64);
                    return Ok(None);
                }
                (header, Frame::Mapped { map: Arc::clone(map), start: at + PORTION_HEADER_BYTES, end })
            }
            Body::Read(file) => {
                let mut head = [0u8; PORTION_HEADER_BYTES];
                let got = read_up_to(file, &mut head).map_err(io)?;
                if got == 0 {
                    return Ok(None);
                }
                if got < PORTION_HEADER_BYTES {
                    self.truncated = Some(got as u64);
                    return Ok(None);
                }
                let header = PortionHeader::from_bytes(&head).map_err(corrupt)?;
                let mut frame = std::mem::take(buffer);
                frame.clear();
                let want = header.compressed as u64;
                // read_to_end fills spare capacity without zeroing it first.
                let got = file.take(want).read_to_end(&mut frame).map_err(io)?;
                if (got as u64) < want {
                    self.truncated = Some((PORTION_HEADER_BYTES + got) as u64);
                    *buffer = frame;
                    return Ok(None);
                }
                (header, Frame::Read(frame))
            }
        };
        self.offset += (PORTION_HEADER_BYTES + header.compressed as usize) as u64;
        Ok(Some(RawPortion { header, frame, file: self.path.clone(), offset }))
    }
}

/// Reads until `buf` is full or the file ends; the bytes read.
fn read_up_to(file: &mut File, buf: &mut [u8]) -> std::io::Result<usize> {
    let mut got = 0;
    while got < buf.len() {
        match file.read(&mut buf[got..]) {
            Ok(0) => break,
            Ok(n) => got += n,
            Err(e) if e.kind() == ErrorKind::Interrupted => {}
            Err(e) => return Err(e),
        }
    }
    Ok(got)
}

/// The stream files of a map: `path` is a stream file (or a pipe), a map folder (`raymap/` of a render), or a render's
/// output folder that holds one. Sorted by name; an error when there is none.
pub fn stream_files(path: &Path) -> Result<Vec<PathBuf>, RayMapError> {
    let name = path.display().to_string();
    // Anything but a folder is taken for a stream: a file, or a pipe that carries one.
    if path.exists() && !path.is_dir() {
        return Ok(vec![path.to_path_buf()]);
    }
    let dir = if path.join("raymap").is_dir() { path.join("raymap") } else { path.to_path_buf() };
    let entries = std::fs::read_dir(&dir).map_err(|source| RayMapError::Io { path: name.clone(), source })?;
    let mut files: Vec<PathBuf> = entries
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|e| e == "pfrm"))
        .collect();
    files.sort();
    if files.is_empty() {
        return Err(RayMapError::NoStreams(dir.display().to_string()));
    }
    Ok(files)
}

/// Opens every stream of a map and checks that they come from one render (the same scene and names).
pub fn open_streams(path: &Path) -> Result<Vec<StreamReader>, RayMapError> {
    let readers: Vec<StreamReader> =
        stream_files(path)?.iter().map(|f| StreamReader::open(f)).collect::<Result<_, _>>()?;
    let first = &readers[0].header;
    for r in &readers[1..] {
        let h = &r.header;
        if h.scene_hash != first.scene_hash || h.objects != first.objects || h.emitters != first.emitters {
            return Err(RayMapError::Mixed {
                first: readers[0].path.display().to_string(),
                other: r.path.display().to_string(),
            });
        }
    }
    Ok(readers)
}

/// Every path of a map, in stream and file order, with the bytes cut from truncated streams: for tests and
/// small maps (selection streams portions instead).
pub fn read_all(path: &Path) -> Result<(MapHeader, Vec<RecordedPath>, u64), RayMapError> {
    let mut readers = open_streams(path)?;
    let header = readers[0].header.clone();
    let (mut paths, mut cut) = (Vec::new(), 0);
    for r in &mut readers {
        while let Some(p) = r.next_portion()? {
            paths.extend(p.decode()?);
        }
        cut += r.truncated_bytes().unwrap_or(0);
    }
    Ok((header, paths, cut))
}
