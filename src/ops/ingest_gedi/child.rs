//! GEDI granules read in a child process, so that a corrupt file ends as one error line.
//!
//! gedisim reads HDF5 through the HDF5 C library, which cannot be made safe against a corrupt
//! file: Debian's 1.10.8 segfaults on a corrupt global-heap reference (docs/robustness.md,
//! "HDF5"). No validation on our side can reach inside the library's structures, so the command
//! line reads each granule in a child process (`gedisim read-granule`, hidden) and takes its shots
//! back as Arrow IPC over a pipe: a crash kills the child only, and the parent reports it as one
//! line naming the file.
//!
//! The protocol on the child's stdout is a sequence of frames: a tag byte, a little-endian u64
//! length, then the payload — [`BATCH`] (one Arrow IPC stream holding one batch) any number of
//! times, then one [`RESULT`] (the JSON of `Result<Vec<BeamReport>>`).

use std::io::{BufReader, BufWriter, Read, Write};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex, OnceLock};
use std::time::{Duration, Instant};

use arrow::array::RecordBatch;
use arrow::ipc::reader::StreamReader;
use arrow::ipc::writer::StreamWriter;
use serde::{Deserialize, Serialize};

use super::{read_granule_in_process, BeamPart, BeamReport, GediOptions, GranulePair};
use crate::error::{Error, Result};

/// The hidden subcommand the child runs.
pub const COMMAND: &str = "read-granule";

/// Frame tags.
const BATCH: u8 = 1;
const RESULT: u8 = 2;

/// Where granules are read, once the command line has said so.
#[derive(Debug, Clone)]
pub struct Reader {
    /// A gedisim binary; its hidden [`COMMAND`] reads one granule.
    pub exe: PathBuf,
    /// How long the parent waits for the child's next bytes before it stops the child as hung:
    /// the longest a healthy child takes to open the files and read one beam.
    pub stall_limit: Duration,
}

/// The default [`Reader::stall_limit`]: far above what opening a granule and reading one beam
/// should take (a child sends each beam as soon as it has read it), short enough that a scheduled
/// job fails instead of hanging.
pub const STALL_LIMIT: Duration = Duration::from_secs(300);

static READER: OnceLock<Reader> = OnceLock::new();

/// From now on, read granules in child processes (the command line calls it first). Without it
/// (the library in other programs) granules are read in-process.
pub fn read_in_children(reader: Reader) {
    let _ = READER.set(reader);
}

/// Where granules are read, if [`read_in_children`] was called.
pub fn reader() -> Option<&'static Reader> {
    READER.get()
}

/// What the parent asks of the child (its one argument, as JSON).
#[derive(Serialize, Deserialize)]
struct Request {
    pair: GranulePair,
    opts: GediOptions,
    /// The beams to read (all, when absent).
    #[serde(default)]
    part: BeamPart,
}

/// The child: read `request`'s granule in this process, writing frames to `out`. A read error
/// travels in the result frame; only a failure to write to `out` is returned.
pub fn serve(request: &str, out: impl Write) -> Result<()> {
    let mut out = BufWriter::new(out);
    let pipe = |e: std::io::Error| Error::Usage(format!("{COMMAND}: writing to the parent: {e}"));
    let result = serde_json::from_str::<Request>(request)
        .map_err(|e| Error::Usage(format!("{COMMAND}: a malformed request: {e}")))
        .and_then(|r| {
            read_granule_in_process(&r.pair, &r.opts, r.part, &mut |batch| {
                let mut bytes = Vec::new();
                let mut w = StreamWriter::try_new(&mut bytes, &batch.schema())
                    .and_then(|mut w| w.write(&batch).and_then(|_| w.finish()));
                w.as_mut().map_err(|e| Error::Usage(format!("{COMMAND}: encoding a batch: {e}")))?;
                frame(&mut out, BATCH, &bytes).map_err(pipe)
            })
        });
    let json = serde_json::to_vec(&result)
        .or_else(|e| serde_json::to_vec(&Result::<Vec<BeamReport>>::Err(Error::Usage(e.to_string()))))
        .map_err(|e| Error::Usage(e.to_string()))?;
    frame(&mut out, RESULT, &json).and_then(|_| out.flush()).map_err(pipe)
}

fn frame(out: &mut impl Write, tag: u8, payload: &[u8]) -> std::io::Result<()> {
    out.write_all(&[tag])?;
    out.write_all(&(payload.len() as u64).to_le_bytes())?;
    out.write_all(payload)
}

/// The parent: read `pair` in `parts` child processes at once, each some of its beams
/// ([`BeamPart`]), handing the batches to `sink` in beam order and the reports in the same order:
/// the first part's batches as they come, the others' once it is done (held until then in an
/// anonymous temporary file, so that memory stays that of one read).
pub fn read_in_parts(
    reader: &Reader,
    pair: &GranulePair,
    opts: &GediOptions,
    parts: usize,
    sink: &mut dyn FnMut(RecordBatch) -> Result<()>,
) -> Result<Vec<BeamReport>> {
    if parts <= 1 {
        return read(reader, pair, opts, BeamPart::WHOLE, sink);
    }
    std::thread::scope(|scope| {
        let others: Vec<_> = (1..parts)
            .map(|index| scope.spawn(move || read_held(reader, pair, opts, BeamPart { index, of: parts })))
            .collect();
        let first = read(reader, pair, opts, BeamPart { index: 0, of: parts }, sink);
        let mut reports = first?;
        for other in others {
            let (held, more) = other.join().unwrap_or_else(|p| std::panic::resume_unwind(p))?;
            held.replay(sink)?;
            reports.extend(more);
        }
        Ok(reports)
    })
}

/// [`read`] of one part, its batches held in a [`Held`].
fn read_held(
    reader: &Reader,
    pair: &GranulePair,
    opts: &GediOptions,
    part: BeamPart,
) -> Result<(Held, Vec<BeamReport>)> {
    let mut held = Held::new()?;
    let reports = read(reader, pair, opts, part, &mut |b| held.hold(&b))?;
    Ok((held, reports))
}

/// Batches held in an anonymous temporary file (Arrow IPC), handed on later in the same order.
struct Held {
    writer: Option<StreamWriter<BufWriter<std::fs::File>>>,
    file: Option<std::fs::File>,
}

impl Held {
    fn new() -> Result<Held> {
        let file =
            tempfile::tempfile().map_err(|e| Error::Usage(format!("a temporary file for a granule's part: {e}")))?;
        Ok(Held { writer: None, file: Some(file) })
    }

    fn failed(e: impl std::fmt::Display) -> Error {
        Error::Usage(format!("holding a granule's part in a temporary file: {e}"))
    }

    fn hold(&mut self, batch: &RecordBatch) -> Result<()> {
        if self.writer.is_none() {
            let file = self.file.take().expect("the file until the first batch");
            self.writer = Some(StreamWriter::try_new(BufWriter::new(file), &batch.schema()).map_err(Held::failed)?);
        }
        self.writer.as_mut().expect("set above").write(batch).map_err(Held::failed)
    }

    /// Hand every batch held to `sink`, in order.
    fn replay(self, sink: &mut dyn FnMut(RecordBatch) -> Result<()>) -> Result<()> {
        use std::io::{Seek, SeekFrom};
        let Some(mut writer) = self.writer else { return Ok(()) };
        writer.finish().map_err(Held::failed)?;
        let mut file = writer.into_inner().map_err(Held::failed)?.into_inner().map_err(Held::failed)?;
        file.seek(SeekFrom::Start(0)).map_err(Held::failed)?;
        for batch in StreamReader::try_new(BufReader::new(file), None).map_err(Held::failed)? {
            sink(batch.map_err(Held::failed)?)?;
        }
        Ok(())
    }
}

/// The parent: read the beams `part` of `pair` in a child process, handing its batches to `sink`.
fn read(
    reader: &Reader,
    pair: &GranulePair,
    opts: &GediOptions,
    part: BeamPart,
    sink: &mut dyn FnMut(RecordBatch) -> Result<()>,
) -> Result<Vec<BeamReport>> {
    let first = pair.l1b.as_deref().or(pair.l2a.as_deref()).unwrap_or(Path::new(""));
    let request = serde_json::to_string(&Request { pair: pair.clone(), opts: opts.clone(), part })
        .map_err(|e| Error::file(first, format!("a path gedisim cannot pass to its granule reader: {e}")))?;
    // The request goes through stdin: an area of thousands of tiles exceeds one argument's length.
    let mut child = Command::new(&reader.exe)
        .args([COMMAND, "-"])
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .map_err(|e| Error::file(&reader.exe, format!("starting the granule reader: {e}")))?;
    let (stdout, mut stderr) = (child.stdout.take().expect("piped"), child.stderr.take().expect("piped"));
    // Written beside the frames' reading; a child that dies first closes the pipe, and its failure
    // is told below from its status and stderr.
    let mut stdin = child.stdin.take().expect("piped");
    let writer = std::thread::spawn(move || {
        let _ = stdin.write_all(request.as_bytes());
    });
    // Drained beside the frames, so that a child writing to stderr never blocks.
    let errors = std::thread::spawn(move || {
        let mut s = String::new();
        let _ = stderr.read_to_string(&mut s);
        s
    });
    let child = Arc::new(Mutex::new(child));
    let watch = Watch::new(reader.stall_limit, Arc::clone(&child));
    let received = receive(BufReader::new(Watched { inner: stdout, watch: &watch }), sink);
    let stalled = watch.stop();
    let _ = writer.join();
    let mut child = child.lock().unwrap_or_else(|e| e.into_inner());
    if received.is_err() {
        let _ = child.kill();
    }
    let status = child.wait().map_err(|e| Error::file(first, format!("waiting for the granule reader: {e}")))?;
    let stderr = errors.join().unwrap_or_default();
    match received {
        Err(e) => Err(e),
        Ok(Some(result)) => result,
        Ok(None) => Err(failed(reader, pair, opts, part, status, stalled, &stderr)),
    }
}

/// Stops a child that the parent has waited on for longer than the stall limit: only the time the
/// parent spends waiting for bytes counts, not the time it spends writing what it received.
struct Watch {
    /// Milliseconds since `start` at which the parent began waiting (0: not waiting).
    waiting_since: Arc<AtomicU64>,
    start: Instant,
    done: Arc<AtomicBool>,
    stalled: Arc<AtomicBool>,
    thread: Option<std::thread::JoinHandle<()>>,
}

impl Watch {
    fn new(limit: Duration, child: Arc<Mutex<std::process::Child>>) -> Watch {
        let waiting_since = Arc::new(AtomicU64::new(0));
        let (done, stalled) = (Arc::new(AtomicBool::new(false)), Arc::new(AtomicBool::new(false)));
        let start = Instant::now();
        let (w, d, s) = (Arc::clone(&waiting_since), Arc::clone(&done), Arc::clone(&stalled));
        let tick = (limit / 10).clamp(Duration::from_millis(10), Duration::from_secs(1));
        let thread = std::thread::spawn(move || {
            while !d.load(Ordering::Acquire) {
                std::thread::park_timeout(tick);
                let since = w.load(Ordering::Acquire);
                if since > 0 && start.elapsed().as_millis() as u64 > since + limit.as_millis() as u64 {
                    s.store(true, Ordering::Release);
                    let _ = child.lock().unwrap_or_else(|e| e.into_inner()).kill();
                    return;
                }
            }
        });
        Watch { waiting_since, start, done, stalled, thread: Some(thread) }
    }

    /// Ends the watch; whether it stopped the child.
    fn stop(mut self) -> bool {
        self.done.store(true, Ordering::Release);
        if let Some(t) = self.thread.take() {
            t.thread().unpark();
            let _ = t.join();
        }
        self.stalled.load(Ordering::Acquire)
    }
}

/// The child's stdout, telling its [`Watch`] when the parent waits on it.
struct Watched<'w, R> {
    inner: R,
    watch: &'w Watch,
}

impl<R: Read> Read for Watched<'_, R> {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        let now = self.watch.start.elapsed().as_millis() as u64;
        self.watch.waiting_since.store(now.max(1), Ordering::Release);
        let n = self.inner.read(buf);
        self.watch.waiting_since.store(0, Ordering::Release);
        n
    }
}

/// The frames of a child: batches to `sink`; the result, or `None` when the child ended first.
fn receive(
    mut from: impl Read,
    sink: &mut dyn FnMut(RecordBatch) -> Result<()>,
) -> Result<Option<Result<Vec<BeamReport>>>> {
    let bad = |what: String| Error::Usage(format!("the granule reader's output: {what}"));
    loop {
        let mut head = [0u8; 9];
        match from.read_exact(&mut head) {
            Ok(()) => {}
            Err(e) if e.kind() == std::io::ErrorKind::UnexpectedEof => return Ok(None),
            Err(e) => return Err(bad(e.to_string())),
        }
        let len = u64::from_le_bytes(head[1..].try_into().expect("8 bytes"));
        let mut payload = Vec::new();
        let got = from.by_ref().take(len).read_to_end(&mut payload).map_err(|e| bad(e.to_string()))?;
        if got as u64 != len {
            return Ok(None);
        }
        match head[0] {
            BATCH => {
                for batch in StreamReader::try_new(payload.as_slice(), None).map_err(|e| bad(e.to_string()))? {
                    sink(batch.map_err(|e| bad(e.to_string()))?)?;
                }
            }
            RESULT => {
                return serde_json::from_slice(&payload).map(Some).map_err(|e| bad(e.to_string()));
            }
            tag => return Err(bad(format!("unknown frame {tag}"))),
        }
    }
}

/// The error of a child that ended without a result: which file of the pair it died on (each
/// file read alone again, when there are two), and how it ended.
fn failed(
    reader: &Reader,
    pair: &GranulePair,
    opts: &GediOptions,
    part: BeamPart,
    status: std::process::ExitStatus,
    stalled: bool,
    stderr: &str,
) -> Error {
    let how = match signal(status) {
        _ if stalled => format!(
            "the HDF5 library made no progress reading this file for {} s and was stopped: it is corrupt \
             (download it again), or its storage stalled",
            reader.stall_limit.as_secs_f64()
        ),
        Some(s) => format!("the HDF5 library crashed reading this file ({s}): it is corrupt; download it again"),
        None => {
            let last = stderr.lines().rev().find(|l| !l.trim().is_empty()).unwrap_or("").trim();
            format!("the granule reader ended without a result ({status}: {last})")
        }
    };
    let alone = |l1b: Option<&PathBuf>, l2a: Option<&PathBuf>| GranulePair {
        granule: pair.granule.clone(),
        l1b: l1b.cloned(),
        l2a: l2a.cloned(),
    };
    match (&pair.l1b, &pair.l2a) {
        (Some(l1b), Some(l2a)) => {
            let fails = |p: GranulePair| read(reader, &p, opts, part, &mut |_| Ok(())).is_err();
            if fails(alone(Some(l1b), None)) {
                Error::file(l1b, how)
            } else if fails(alone(None, Some(l2a))) {
                Error::file(l2a, how)
            } else {
                Error::file(l1b, format!("read with {}: {how} (each file alone reads)", l2a.display()))
            }
        }
        (Some(p), None) | (None, Some(p)) => Error::file(p, how),
        (None, None) => Error::Usage(how),
    }
}

/// The signal that ended a process, named.
fn signal(status: std::process::ExitStatus) -> Option<String> {
    #[cfg(unix)]
    if let Some(signal) = std::os::unix::process::ExitStatusExt::signal(&status) {
        let name = match signal {
            6 => ", SIGABRT",
            7 => ", SIGBUS",
            9 => ", SIGKILL",
            11 => ", SIGSEGV",
            _ => "",
        };
        return Some(format!("signal {signal}{name}"));
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ops::ingest_gedi::{expand_granule_inputs, pair_granules};

    fn bundled_pair() -> GranulePair {
        let dir = [PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/data/gedi")];
        let l1b = expand_granule_inputs(&dir, "GEDI01_B").unwrap();
        let l2a = expand_granule_inputs(&dir, "GEDI02_A").unwrap();
        pair_granules(&l1b, &l2a).unwrap().0.remove(0)
    }

    /// What the child writes, the parent reads back: the same batches and reports as a read in
    /// this process; a stream cut short is a child that ended without a result.
    #[test]
    fn the_frames_carry_the_granule_unchanged() {
        let pair = bundled_pair();
        let opts = GediOptions::default();
        let mut here = Vec::new();
        let reports = read_granule_in_process(&pair, &opts, BeamPart::WHOLE, &mut |b| {
            here.push(b);
            Ok(())
        })
        .unwrap();
        let mut bytes = Vec::new();
        let request = Request { pair: pair.clone(), opts, part: BeamPart::WHOLE };
        serve(&serde_json::to_string(&request).unwrap(), &mut bytes).unwrap();
        let mut there = Vec::new();
        let result = receive(bytes.as_slice(), &mut |b| {
            there.push(b);
            Ok(())
        })
        .unwrap();
        assert_eq!(result.unwrap().unwrap(), reports);
        assert!(!here.is_empty());
        assert_eq!(there, here);
        assert!(receive(&bytes[..bytes.len() - 3], &mut |_| Ok(())).unwrap().is_none());
    }

    /// A read error travels back as the same error, not as a crash.
    #[test]
    fn a_read_error_comes_back_as_it_was() {
        let pair =
            GranulePair { granule: "g".into(), l1b: Some(PathBuf::from("/nonexistent/GEDI01_B_x.h5")), l2a: None };
        let opts = GediOptions::default();
        let expected = read_granule_in_process(&pair, &opts, BeamPart::WHOLE, &mut |_| Ok(())).unwrap_err().to_string();
        let mut bytes = Vec::new();
        serve(&serde_json::to_string(&Request { pair, opts, part: BeamPart::WHOLE }).unwrap(), &mut bytes).unwrap();
        let got = receive(bytes.as_slice(), &mut |_| Ok(())).unwrap().unwrap().unwrap_err();
        assert_eq!(got.to_string(), expected);
        assert!(matches!(got, Error::File { .. } | Error::Field { .. }), "{got:?}");
    }
}
