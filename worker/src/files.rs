//! The files a job's scene references, as the worker receives them: pieces assembled in order and checked
//! against their SHA-256, and a cache that a daemon keeps from job to job while a one-job worker lets each
//! file go once its scene is built.

use photonfarm::protocol::{FilePiece, FileRef, ProtocolError, FILE_PIECE_BYTES};
use sha2::{Digest, Sha256};
use std::collections::BTreeMap;

/// Files received, by SHA-256.
#[derive(Debug, Default)]
pub struct FileCache {
    files: BTreeMap<String, Vec<u8>>,
    keep: bool,
}

impl FileCache {
    /// A cache for a worker that serves one job: the scene's files are dropped once it is built.
    pub fn for_one_job() -> Self {
        FileCache { files: BTreeMap::new(), keep: false }
    }

    /// A cache for a daemon: files stay for the next jobs that name them.
    pub fn kept_between_jobs() -> Self {
        FileCache { files: BTreeMap::new(), keep: true }
    }

    /// Whether the file with this hash is here.
    pub fn contains(&self, sha256: &str) -> bool {
        self.files.contains_key(sha256)
    }

    /// Files held.
    pub fn len(&self) -> usize {
        self.files.len()
    }

    /// Whether no file is held.
    pub fn is_empty(&self) -> bool {
        self.files.is_empty()
    }

    /// Adds a received file.
    pub fn insert(&mut self, sha256: String, bytes: Vec<u8>) {
        self.files.insert(sha256, bytes);
    }

    /// The job's files by their paths, moved out of the cache rather than copied (a path named twice with the
    /// same content is the one copy made); the path of the first one missing when one is. Each was checked
    /// against its hash as it arrived, so the scene is built without hashing them again.
    pub fn take(&mut self, files: &[FileRef]) -> Result<BTreeMap<String, Vec<u8>>, String> {
        let mut by_path = BTreeMap::new();
        let mut first_path: BTreeMap<&str, &str> = BTreeMap::new();
        for f in files {
            let bytes = match first_path.get(f.sha256.as_str()) {
                Some(path) => by_path.get(*path).cloned().unwrap_or_default(),
                None => self.files.remove(&f.sha256).ok_or_else(|| f.path.clone())?,
            };
            first_path.entry(f.sha256.as_str()).or_insert(f.path.as_str());
            by_path.insert(f.path.clone(), bytes);
        }
        Ok(by_path)
    }

    /// Hands back what `take` gave, once the scene is built: a daemon's cache keeps the files, a one-job
    /// worker's drops them.
    pub fn give_back(&mut self, files: &[FileRef], mut by_path: BTreeMap<String, Vec<u8>>) {
        if !self.keep {
            return;
        }
        for f in files {
            if let Some(bytes) = by_path.remove(&f.path) {
                self.files.entry(f.sha256.clone()).or_insert(bytes);
            }
        }
    }
}

/// Files on their way: the pieces received so far of each file asked for.
#[derive(Debug)]
pub struct Arrivals {
    pending: BTreeMap<String, Partial>,
}

#[derive(Debug, Default)]
struct Partial {
    size: Option<u64>,
    bytes: Vec<u8>,
    hasher: Sha256,
}

impl Arrivals {
    /// Expects the files with these hashes.
    pub fn expecting(hashes: &[String]) -> Self {
        Arrivals { pending: hashes.iter().map(|h| (h.clone(), Partial::default())).collect() }
    }

    /// Whether every file asked for arrived whole.
    pub fn is_done(&self) -> bool {
        self.pending.is_empty()
    }

    /// Takes one piece; returns the file once its last piece is in and its hash checked. A piece of a file not
    /// asked for, out of order, beyond the file's size or of another size than the file's first piece, and a
    /// file whose bytes do not hash to its name, are refused.
    pub fn receive(&mut self, piece: FilePiece) -> Result<Option<(String, Vec<u8>)>, ProtocolError> {
        let FilePiece { sha256, size, offset, bytes } = piece;
        let malformed = |what: String| Err(ProtocolError::Malformed(format!("file {sha256}: {what}")));
        let Some(partial) = self.pending.get_mut(&sha256) else {
            return Err(ProtocolError::Malformed(format!("a piece of a file that was not asked for ({sha256})")));
        };
        match partial.size {
            None => {
                if partial.bytes.try_reserve_exact(usize::try_from(size).unwrap_or(usize::MAX)).is_err() {
                    return malformed(format!("{size} bytes do not fit this worker's memory"));
                }
                partial.size = Some(size);
            }
            Some(s) if s != size => return malformed(format!("a piece says {size} bytes, the first said {s}")),
            Some(_) => {}
        }
        let have = partial.bytes.len() as u64;
        if offset != have {
            return malformed(format!("a piece at byte {offset}, expected at {have}"));
        }
        if bytes.len() > FILE_PIECE_BYTES || (bytes.is_empty() && size > 0) {
            return malformed(format!("a piece of {} bytes", bytes.len()));
        }
        if have + bytes.len() as u64 > size {
            return malformed(format!("pieces beyond its {size} bytes"));
        }
        partial.hasher.update(&bytes);
        partial.bytes.extend_from_slice(&bytes);
        if (partial.bytes.len() as u64) < size {
            return Ok(None);
        }
        let partial = self.pending.remove(&sha256).expect("the file is pending");
        let actual = format!("{:x}", partial.hasher.finalize());
        if actual != sha256 {
            return malformed(format!("arrived with hash {actual}"));
        }
        Ok(Some((sha256, partial.bytes)))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn hash(bytes: &[u8]) -> String {
        format!("{:x}", Sha256::digest(bytes))
    }

    fn file(len: usize) -> Vec<u8> {
        (0..len).map(|i| (i * 7 % 253) as u8).collect()
    }

    #[test]
    fn pieces_assemble_into_the_file_they_came_from() {
        for len in [0, 1, FILE_PIECE_BYTES, FILE_PIECE_BYTES + 3] {
            let bytes = file(len);
            let h = hash(&bytes);
            let mut arrivals = Arrivals::expecting(std::slice::from_ref(&h));
            let pieces = FilePiece::all_of(&h, &bytes);
            let last = pieces.len() - 1;
            for (i, p) in pieces.into_iter().enumerate() {
                let got = arrivals.receive(p).unwrap();
                assert_eq!(got.is_some(), i == last, "piece {i} of a {len}-byte file");
                if let Some((name, whole)) = got {
                    assert_eq!((name, whole), (h.clone(), bytes.clone()));
                }
            }
            assert!(arrivals.is_done());
        }
    }

    #[test]
    fn damaged_reordered_oversized_and_unasked_pieces_are_refused() {
        let bytes = file(FILE_PIECE_BYTES + 10);
        let h = hash(&bytes);
        let pieces = FilePiece::all_of(&h, &bytes);
        let refused = |piece: FilePiece, before: &[FilePiece]| {
            let mut arrivals = Arrivals::expecting(std::slice::from_ref(&h));
            for p in before {
                arrivals.receive(p.clone()).unwrap();
            }
            arrivals.receive(piece).unwrap_err().to_string()
        };
        // Out of order.
        assert!(refused(pieces[1].clone(), &[]).contains("expected at 0"));
        // Another size than the first piece's.
        let resized = FilePiece { size: bytes.len() as u64 + 1, ..pieces[1].clone() };
        assert!(refused(resized, &pieces[..1]).contains("the first said"));
        // Beyond the file's end.
        let long = FilePiece { bytes: vec![0; 11], ..pieces[1].clone() };
        assert!(refused(long, &pieces[..1]).contains("beyond"));
        // Damaged on the way.
        let mut damaged = pieces[1].clone();
        damaged.bytes[0] ^= 1;
        assert!(refused(damaged, &pieces[..1]).contains("arrived with hash"));
        // Not asked for.
        let other = FilePiece::all_of(&hash(b"x"), b"x").remove(0);
        assert!(refused(other, &[]).contains("not asked for"));
        // A size no memory holds.
        let huge = FilePiece { size: u64::MAX, ..pieces[0].clone() };
        assert!(refused(huge, &[]).contains("do not fit"));
    }

    #[test]
    fn a_one_job_cache_lets_its_files_go_and_a_daemon_s_keeps_them() {
        let refs = vec![
            FileRef { path: "a.obj".into(), sha256: "h1".into() },
            FileRef { path: "copy-of-a.obj".into(), sha256: "h1".into() },
            FileRef { path: "b.obj".into(), sha256: "h2".into() },
        ];
        for (mut cache, kept) in [(FileCache::for_one_job(), 0), (FileCache::kept_between_jobs(), 2)] {
            cache.insert("h1".into(), b"one".to_vec());
            cache.insert("h2".into(), b"two".to_vec());
            let files = cache.take(&refs).unwrap();
            assert_eq!(files["a.obj"], b"one");
            assert_eq!(files["copy-of-a.obj"], b"one");
            assert_eq!(files["b.obj"], b"two");
            assert!(cache.is_empty(), "the files were moved out, not copied");
            cache.give_back(&refs, files);
            assert_eq!(cache.len(), kept);
            if kept > 0 {
                assert!(cache.contains("h1") && cache.contains("h2"));
            }
        }
    }

    #[test]
    fn taking_a_file_that_never_arrived_names_it_rather_than_giving_it_empty() {
        let mut cache = FileCache::for_one_job();
        cache.insert("h1".into(), b"one".to_vec());
        let refs = vec![
            FileRef { path: "a.obj".into(), sha256: "h1".into() },
            FileRef { path: "b.obj".into(), sha256: "h2".into() },
        ];
        assert_eq!(cache.take(&refs), Err("b.obj".to_string()));
    }
}
