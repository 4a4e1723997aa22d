//! The spill file of a whole-tile ingest: a chunk's points, filed by cell, appended as runs (one
//! cell each, column by column) and read back cell by cell.

use std::fs::File;
use std::io::{BufWriter, Read, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};

use crate::error::{Error, Result};
use crate::kernels::sim::AlsPoints;

/// One run of points of a single cell in the spill file.
#[derive(Clone, Copy)]
pub(super) struct Run {
    pub(super) cell: u64,
    pub(super) offset: u64,
    pub(super) len: u32,
}

/// Bytes of one spilled point: x, y, z, gps (f64), scan angle (f32), intensity, psid (u16),
/// return number, number of returns, class (u8). A run stores each column contiguously.
const SPILL_RECORD: usize = 8 * 4 + 4 + 2 * 2 + 3;

/// Write side of the spill file.
pub(super) struct SpillFile {
    path: PathBuf,
    out: BufWriter<File>,
    offset: u64,
    buf: Vec<u8>,
}

impl SpillFile {
    pub(super) fn create(path: &Path) -> Result<Self> {
        let f = File::create(path).map_err(|e| Error::file(path, format!("cannot create spill file: {e}")))?;
        Ok(SpillFile {
            path: path.to_path_buf(),
            out: BufWriter::with_capacity(1 << 20, f),
            offset: 0,
            buf: Vec::new(),
        })
    }

    /// Append the points `order` (sorted by cell) of `chunk`, one run per cell, column by column.
    pub(super) fn write_runs(&mut self, chunk: &AlsPoints, order: &[(u64, u32)], runs: &mut Vec<Run>) -> Result<()> {
        fn put<T: Copy, const N: usize>(
            buf: &mut Vec<u8>,
            col: &[T],
            idx: &[(u64, u32)],
            bytes: impl Fn(T) -> [u8; N],
        ) {
            for &(_, i) in idx {
                buf.extend_from_slice(&bytes(col[i as usize]));
            }
        }
        self.buf.clear();
        self.buf.reserve(order.len() * SPILL_RECORD);
        let mut start = 0;
        while start < order.len() {
            let cell = order[start].0;
            let end = start + order[start..].partition_point(|&(c, _)| c == cell);
            let (idx, buf) = (&order[start..end], &mut self.buf);
            runs.push(Run { cell, offset: self.offset + buf.len() as u64, len: idx.len() as u32 });
            put(buf, &chunk.x, idx, f64::to_le_bytes);
            put(buf, &chunk.y, idx, f64::to_le_bytes);
            put(buf, &chunk.z, idx, f64::to_le_bytes);
            put(buf, &chunk.gps_time, idx, f64::to_le_bytes);
            put(buf, &chunk.scan_angle_deg, idx, f32::to_le_bytes);
            put(buf, &chunk.intensity, idx, u16::to_le_bytes);
            put(buf, &chunk.point_source_id, idx, u16::to_le_bytes);
            put(buf, &chunk.return_number, idx, |v: u8| [v]);
            put(buf, &chunk.number_of_returns, idx, |v: u8| [v]);
            put(buf, &chunk.classification, idx, |v: u8| [v]);
            start = end;
        }
        self.out.write_all(&self.buf).map_err(|e| Error::file(&self.path, format!("cannot write spill file: {e}")))?;
        self.offset += self.buf.len() as u64;
        Ok(())
    }

    pub(super) fn finish(mut self) -> Result<PathBuf> {
        self.out.flush().map_err(|e| Error::file(&self.path, format!("cannot write spill file: {e}")))?;
        Ok(self.path)
    }
}

/// Read side of the spill file.
pub(super) struct SpillReader {
    path: PathBuf,
    file: File,
    buf: Vec<u8>,
}

impl SpillReader {
    pub(super) fn open(path: &Path) -> Result<Self> {
        let file = File::open(path).map_err(|e| Error::file(path, format!("cannot open spill file: {e}")))?;
        Ok(SpillReader { path: path.to_path_buf(), file, buf: Vec::new() })
    }

    pub(super) fn read_runs(&mut self, runs: &[Run]) -> Result<AlsPoints> {
        fn take<T, const N: usize>(
            col: &mut Vec<T>,
            bytes: &[u8],
            at: &mut usize,
            n: usize,
            from: impl Fn([u8; N]) -> T,
        ) {
            let part = &bytes[*at..*at + n * N];
            col.extend(part.chunks_exact(N).map(|c| from(c.try_into().expect("N bytes"))));
            *at += n * N;
        }
        let total: usize = runs.iter().map(|r| r.len as usize).sum();
        let mut p = AlsPoints::with_capacity(total);
        for r in runs {
            let n = r.len as usize;
            self.buf.resize(n * SPILL_RECORD, 0);
            self.file
                .seek(SeekFrom::Start(r.offset))
                .and_then(|_| self.file.read_exact(&mut self.buf))
                .map_err(|e| Error::file(&self.path, format!("cannot read spill file: {e}")))?;
            let (b, at) = (&self.buf, &mut 0);
            take(&mut p.x, b, at, n, f64::from_le_bytes);
            take(&mut p.y, b, at, n, f64::from_le_bytes);
            take(&mut p.z, b, at, n, f64::from_le_bytes);
            take(&mut p.gps_time, b, at, n, f64::from_le_bytes);
            take(&mut p.scan_angle_deg, b, at, n, f32::from_le_bytes);
            take(&mut p.intensity, b, at, n, u16::from_le_bytes);
            take(&mut p.point_source_id, b, at, n, u16::from_le_bytes);
            take(&mut p.return_number, b, at, n, |[v]: [u8; 1]| v);
            take(&mut p.number_of_returns, b, at, n, |[v]: [u8; 1]| v);
            take(&mut p.classification, b, at, n, |[v]: [u8; 1]| v);
        }
        Ok(p)
    }
}
