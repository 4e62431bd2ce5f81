//! `trace.csv`, written as the run goes: one row per actuator step kept (`--trace-every N`:
//! steps 1, 1 + N, … and the run's last), each row written when its step happens rather
//! than the run's step records kept until it ends. A record is about a kilobyte
//! (`runlog::StepRecord`, 1 064 bytes for a graph of up to 7 topics) and the actuator steps
//! 50 times a second of run time, so a day's records were 4.6 GB, which a day-long run with
//! `--out` could not allocate (issue 75); a row of the file is about 110 bytes, and what is
//! held meanwhile is one chunk of rows ([`CHUNK`]) and the newest step not yet written.
//!
//! The bytes are those the run's kept records gave, written at its end: the same columns,
//! the same cells (the module's tests compare them). One difference is possible in
//! principle, none in practice: the file's QoS columns are fixed when it starts, from the
//! graph's QoS ([`qos_columns`] with no record), where the end's records could add one for a
//! counter that counted without its QoS enabling it. The headless run and `ratelab.run`
//! apply no command that changes a topic's QoS, and a counter counts only under the QoS
//! that enables it ([`ratelab_core::qos::QosCounter::enabled_by`]), so the two are the same.
//!
//! Rows reach the file whole, a chunk at a time: a file cut short (the process killed) ends
//! at a row's end. A write that fails (a full disk) empties the file, giving its space
//! back to the run's other files, and the run goes on (a warning says so at once); the
//! failure is the run's error once its summary and its other files are written, as any
//! output's is.

use ratelab_core::output::{OutputError, PendingFile};
use ratelab_core::qos::QosCounter;
use ratelab_core::runlog::{StepRecord, TopicCounters};
use ratelab_runtime::graph::{GraphSpec, StepObserver, TopicId};
use std::io::Write;
use std::path::Path;
use std::sync::{Arc, Mutex, MutexGuard};

/// Rows gathered before they are written out together, bytes (at least: a chunk ends with
/// the row that reaches it).
pub const CHUNK: usize = 64 << 10;

/// Where `trace.csv`'s rows go: its (temporary) file, or memory (`ratelab.run`).
pub trait TraceSink: Write + Send + 'static {
    /// A write failed: give back what was written (a full disk's space, for the other
    /// outputs).
    fn discard(&mut self);
}

impl TraceSink for std::fs::File {
    fn discard(&mut self) {
        let _ = self.set_len(0);
    }
}

impl TraceSink for Vec<u8> {
    fn discard(&mut self) {
        self.clear();
    }
}

/// Each topic's QoS counter columns, in the graph's topic order: those its QoS enables, and
/// those `last` (the run's last record, when known) counted.
pub fn qos_columns(graph: &GraphSpec, last: Option<&TopicCounters>) -> Vec<Vec<QosCounter>> {
    let none = TopicCounters::default();
    let last = last.unwrap_or(&none);
    graph
        .topics
        .iter()
        .enumerate()
        .map(|(i, t)| last.get(TopicId(i)).reported(&[t.qos]))
        .collect()
}

/// How many columns `trace.csv` of `graph` has (its values per row).
pub fn column_count(graph: &GraphSpec) -> usize {
    header(graph, &qos_columns(graph, None)).len()
}

/// The header: the step's columns; per topic (in the graph's topic order) a
/// `<topic>_published` and `<topic>_dropped` column (`/obs` → `obs_published`), as the
/// chapter's trace has; then `<topic>_<counter>` for each QoS counter of `qos`; then `fell`.
fn header(graph: &GraphSpec, qos: &[Vec<QosCounter>]) -> Vec<String> {
    let mut header: Vec<String> = [
        "step",
        "t_ns",
        "pole_angle",
        "cart_pos",
        "action",
        "latency_ns",
        "nonfinite",
    ]
    .map(String::from)
    .to_vec();
    for t in &graph.topics {
        let name = ratelab_recording::bus_name(&t.name);
        header.push(format!("{name}_published"));
        header.push(format!("{name}_dropped"));
    }
    for (t, counters) in graph.topics.iter().zip(qos) {
        let name = ratelab_recording::bus_name(&t.name);
        for c in counters {
            header.push(format!("{name}_{}", c.key()));
        }
    }
    header.push("fell".into());
    header
}

/// One step's row, under [`header`]'s columns.
fn cells(r: &StepRecord, qos: &[Vec<QosCounter>]) -> Vec<String> {
    let mut row = vec![
        r.step.to_string(),
        r.t.0.to_string(),
        format!("{:e}", r.pole_angle),
        format!("{:e}", r.cart_pos),
        format!("{:e}", r.action),
        r.latency.map_or_else(String::new, |l| l.0.to_string()),
        r.nonfinite.to_string(),
    ];
    for t in r.topics.iter() {
        row.push(t.published.to_string());
        row.push(t.dropped.to_string());
    }
    for (t, counters) in r.topics.iter().zip(qos) {
        for c in counters {
            row.push(t.counter(*c).to_string());
        }
    }
    row.push(r.fell.to_string());
    row
}

/// The CSV writer's output: whole rows gathered, written to `out` a [`CHUNK`] at a time
/// (when the CSV writer is flushed, after each row) and at the end ([`Rows::spill`]).
struct Rows<W: TraceSink> {
    out: W,
    buf: Vec<u8>,
    failed: bool,
}

fn failed_before() -> std::io::Error {
    std::io::Error::other("an earlier write of trace.csv failed")
}

impl<W: TraceSink> Rows<W> {
    /// Write what is gathered to `out`. A failure empties `out` and ends the writing.
    fn spill(&mut self) -> std::io::Result<()> {
        if self.failed {
            return Err(failed_before());
        }
        if let Err(e) = self.out.write_all(&self.buf) {
            self.failed = true;
            self.buf = Vec::new();
            self.out.discard();
            return Err(e);
        }
        self.buf.clear();
        Ok(())
    }
}

impl<W: TraceSink> Write for Rows<W> {
    fn write(&mut self, bytes: &[u8]) -> std::io::Result<usize> {
        if self.failed {
            return Err(failed_before());
        }
        self.buf.extend_from_slice(bytes);
        Ok(bytes.len())
    }

    fn flush(&mut self) -> std::io::Result<()> {
        if self.failed {
            return Err(failed_before());
        }
        if self.buf.len() >= CHUNK {
            self.spill()?;
        }
        Ok(())
    }
}

/// `trace.csv` written row by row to `out`: its header when made, then one row per
/// [`TraceWriter::row`], the bytes the whole trace written at once gives.
pub struct TraceWriter<W: TraceSink> {
    csv: csv::Writer<Rows<W>>,
    qos: Vec<Vec<QosCounter>>,
}

impl<W: TraceSink> TraceWriter<W> {
    /// Write the header of `graph`'s trace with the QoS columns `qos` ([`qos_columns`]).
    ///
    /// # Errors
    /// A failed write.
    pub fn new(out: W, graph: &GraphSpec, qos: Vec<Vec<QosCounter>>) -> std::io::Result<Self> {
        let rows = Rows {
            out,
            buf: Vec::new(),
            failed: false,
        };
        let mut csv = csv::Writer::from_writer(rows);
        csv.write_record(header(graph, &qos))?;
        csv.flush()?;
        Ok(Self { csv, qos })
    }

    /// Write step `r`'s row.
    ///
    /// # Errors
    /// A failed write (then nothing more is written, and what was is given back).
    pub fn row(&mut self, r: &StepRecord) -> std::io::Result<()> {
        self.csv.write_record(cells(r, &self.qos))?;
        // The row into the gathered rows; a chunk of them out.
        self.csv.flush()
    }

    /// Write out what is gathered and give `out` back.
    ///
    /// # Errors
    /// A failed write.
    pub fn finish(self) -> std::io::Result<W> {
        let mut rows = self
            .csv
            .into_inner()
            .map_err(csv::IntoInnerError::into_error)?;
        rows.spill()?;
        Ok(rows.out)
    }
}

/// What the run's observer and [`TraceStream::finish`] share.
struct Shared<W: TraceSink> {
    /// `None` once finished, or after a failed write.
    writer: Option<TraceWriter<W>>,
    /// `--trace-every`: rows of steps 1, 1 + every, …
    every: u64,
    /// The newest step not written (thinned out): written at the end, as the run's last.
    unwritten: Option<StepRecord>,
    /// The first failed write.
    error: Option<std::io::Error>,
}

fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    m.lock().unwrap_or_else(|e| e.into_inner())
}

/// `trace.csv` of one run, written as it goes: attach [`TraceStream::observer`] to the run
/// (it writes each step kept as it happens, on the actuator's thread), then
/// [`TraceStream::finish`] it once the run has ended. The rows are the run log's when it
/// keeps every `every`-th record and the last (`ratelab_core::runlog::RunLog::push`,
/// `crate::run::run`).
pub struct TraceStream<W: TraceSink> {
    shared: Arc<Mutex<Shared<W>>>,
}

impl<W: TraceSink> TraceStream<W> {
    /// Start `graph`'s trace in `out` (its header), keeping one step in `every` (0 and 1:
    /// every step) and the last.
    ///
    /// # Errors
    /// The header's write failed.
    pub fn new(out: W, graph: &GraphSpec, every: u64) -> std::io::Result<Self> {
        let writer = TraceWriter::new(out, graph, qos_columns(graph, None))?;
        Ok(Self {
            shared: Arc::new(Mutex::new(Shared {
                writer: Some(writer),
                every: every.max(1),
                unwritten: None,
                error: None,
            })),
        })
    }

    /// The step observer that writes the rows; give it to the run.
    pub fn observer(&self) -> Box<dyn StepObserver> {
        Box::new(TraceObserver(self.shared.clone()))
    }

    /// The run has ended: write its last step when it was thinned out, and everything
    /// gathered; give `out` back. Steps the observer is told of afterwards are not written.
    ///
    /// # Errors
    /// The first write that failed, during the run or now.
    pub fn finish(self) -> std::io::Result<W> {
        let mut shared = lock(&self.shared);
        let shared = &mut *shared;
        let writer = shared.writer.take();
        if let Some(e) = shared.error.take() {
            return Err(e);
        }
        let mut writer = writer.ok_or_else(failed_before)?;
        if let Some(last) = shared.unwritten.take() {
            writer.row(&last)?;
        }
        writer.finish()
    }
}

/// Writes each step kept to the trace ([`TraceStream`]).
struct TraceObserver<W: TraceSink>(Arc<Mutex<Shared<W>>>);

impl<W: TraceSink> StepObserver for TraceObserver<W> {
    fn on_step(&mut self, rec: &StepRecord) {
        let mut shared = lock(&self.0);
        let shared = &mut *shared;
        let Some(writer) = shared.writer.as_mut() else {
            return; // finished, or a write failed
        };
        // The run log's rule: steps 1, 1 + every, … (`RunLog::push`).
        if rec.step.saturating_sub(1) % shared.every == 0 {
            shared.unwritten = None;
            if let Err(e) = writer.row(rec) {
                // Said now, not only at the end of what may be a long run.
                eprintln!(
                    "[ratelab] warning: cannot write trace.csv: {e}; the run goes on without it, and ends in this error once its summary and other files are written"
                );
                shared.error = Some(e);
                shared.writer = None;
            }
        } else {
            shared.unwritten = Some(rec.clone());
        }
    }
}

/// `trace.csv` streamed to a temporary file beside its name as the run goes, moved into
/// place by [`TraceFile::commit`] ([`ratelab_core::output`]'s rule: never over a file without
/// `--force`, never through a link; removed when dropped uncommitted).
pub struct TraceFile {
    pending: PendingFile,
    stream: TraceStream<std::fs::File>,
}

impl TraceFile {
    /// Check `path` and start its trace (the header) before the run, keeping one step in
    /// `every` and the last.
    ///
    /// # Errors
    /// [`OutputError`]: the file is there without `force`, a link or not a regular file, or
    /// the temporary file cannot be made or written.
    pub fn create(
        path: &Path,
        force: bool,
        graph: &GraphSpec,
        every: u64,
    ) -> Result<Self, OutputError> {
        let (pending, file) = PendingFile::create(path, force)?;
        let stream = TraceStream::new(file, graph, every).map_err(|e| OutputError::io(path, &e))?;
        Ok(Self { pending, stream })
    }

    /// The step observer that writes the rows; give it to the run.
    pub fn observer(&self) -> Box<dyn StepObserver> {
        self.stream.observer()
    }

    /// The run has ended: finish the trace ([`TraceStream::finish`]), put it on disk and move
    /// it to its name.
    ///
    /// # Errors
    /// [`OutputError`] naming the file: a write failed (during the run or now), or the name
    /// was taken meanwhile; the temporary file is removed.
    pub fn commit(self) -> Result<(), OutputError> {
        let Self {
            mut pending,
            stream,
        } = self;
        let path = pending.path().to_path_buf();
        let file = stream.finish().map_err(|e| OutputError::io(&path, &e))?;
        file.sync_all().map_err(|e| OutputError::io(&path, &e))?;
        drop(file);
        pending.commit()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::run::{run, RunOptions};
    use ratelab_core::runlog::RunLog;
    use ratelab_core::topic::TopicStats;
    use ratelab_core::Nanos;
    use ratelab_runtime::policy::Scripted;
    use ratelab_runtime::{ClockKind, RunConfig};

    /// `trace.csv` as it was written before it streamed: from every record the run kept,
    /// at its end (`headless::write_trace` at 9d7223d, verbatim).
    fn written_at_the_end(trace: &[StepRecord], graph: &GraphSpec) -> Vec<u8> {
        let mut out = Vec::new();
        {
            let out: &mut dyn Write = &mut out;
            let last = trace.last().map(|r| r.topics.clone()).unwrap_or_default();
            let qos_columns: Vec<Vec<QosCounter>> = graph
                .topics
                .iter()
                .enumerate()
                .map(|(i, t)| last.get(TopicId(i)).reported(&[t.qos]))
                .collect();
            let mut w = csv::Writer::from_writer(out);
            let mut header: Vec<String> = [
                "step",
                "t_ns",
                "pole_angle",
                "cart_pos",
                "action",
                "latency_ns",
                "nonfinite",
            ]
            .map(String::from)
            .to_vec();
            for t in &graph.topics {
                let name = ratelab_recording::bus_name(&t.name);
                header.push(format!("{name}_published"));
                header.push(format!("{name}_dropped"));
            }
            for (t, counters) in graph.topics.iter().zip(&qos_columns) {
                let name = ratelab_recording::bus_name(&t.name);
                for c in counters {
                    header.push(format!("{name}_{}", c.key()));
                }
            }
            header.push("fell".into());
            w.write_record(&header).unwrap();
            for r in trace {
                let mut row = vec![
                    r.step.to_string(),
                    r.t.0.to_string(),
                    format!("{:e}", r.pole_angle),
                    format!("{:e}", r.cart_pos),
                    format!("{:e}", r.action),
                    r.latency.map_or_else(String::new, |l| l.0.to_string()),
                    r.nonfinite.to_string(),
                ];
                for t in r.topics.iter() {
                    row.push(t.published.to_string());
                    row.push(t.dropped.to_string());
                }
                for (t, counters) in r.topics.iter().zip(&qos_columns) {
                    for c in counters {
                        row.push(t.counter(*c).to_string());
                    }
                }
                row.push(r.fell.to_string());
                w.write_record(&row).unwrap();
            }
            w.flush().unwrap();
        }
        out
    }

    /// A virtual run of `secs` s of `cfg`'s graph, its trace kept in memory (as before) and
    /// streamed (now), one step in `every`: (the bytes written at the end, those streamed).
    fn both_ways(mut cfg: RunConfig, secs: u64, every: u64) -> (Vec<u8>, Vec<u8>) {
        cfg.clock = ClockKind::Virtual;
        cfg.duration = Nanos(secs * Nanos::SECOND.0);
        let stream = TraceStream::new(Vec::new(), &cfg.graph, every).unwrap();
        let opts = RunOptions {
            observers: vec![crate::observer::steps(stream.observer())],
            trace_every: every,
            ..RunOptions::new()
        };
        let report = run(&cfg, Box::new(Scripted), opts).unwrap();
        assert!(!report.trace.is_empty());
        let at_the_end = written_at_the_end(&report.trace, &cfg.graph);
        (at_the_end, stream.finish().unwrap())
    }

    #[test]
    fn a_streamed_trace_is_the_trace_written_at_the_end_byte_for_byte() {
        // The chapter's graph; a deadline's counters (QoS columns); a lossy link's; a run
        // that falls (5 Hz control: its last step is the fall).
        let mut deadline = RunConfig::default();
        deadline.graph.set_qos("/action", "deadline_ms=40").unwrap();
        let mut lossy = RunConfig::default();
        lossy
            .graph
            .set_qos("/action", "loss=0.2,delay_ms=10,jitter_ms=3")
            .unwrap();
        let mut falls = RunConfig::default();
        falls.set_control_hz(5.0).unwrap();
        for (name, cfg) in [
            ("chapter", RunConfig::default()),
            ("deadline", deadline),
            ("lossy", lossy),
            ("falls", falls),
        ] {
            // Every step; one in 7 (the last step thinned out, then written); one in 4 (the
            // last step written in turn at 10 s: step 501 = 1 + 4 × 125).
            for every in [1, 7, 4] {
                let (at_the_end, streamed) = both_ways(cfg.clone(), 10, every);
                assert!(
                    at_the_end == streamed,
                    "{name}, one step in {every}: the streamed trace differs:\n{}\n--- at the end:\n{}",
                    String::from_utf8_lossy(&streamed[..streamed.len().min(2000)]),
                    String::from_utf8_lossy(&at_the_end[..at_the_end.len().min(2000)]),
                );
            }
        }
    }

    fn record(step: u64, topics: &TopicCounters) -> StepRecord {
        StepRecord {
            step,
            t: Nanos(step * 20_000_000),
            pole_angle: -1.5e-3 * step as f64,
            pole_angvel: 0.0,
            cart_pos: 0.25,
            action: if step % 3 == 0 { f64::NAN } else { 0.5 },
            latency: (step > 2).then_some(Nanos(40_000_000)),
            held_stamp: None,
            nonfinite: step % 5 == 0,
            topics: topics.clone(),
            published: None,
            fell: false,
            estimate: None,
        }
    }

    /// A sink that keeps each write apart.
    struct Writes(Vec<Vec<u8>>);

    impl Write for Writes {
        fn write(&mut self, bytes: &[u8]) -> std::io::Result<usize> {
            self.0.push(bytes.to_vec());
            Ok(bytes.len())
        }
        fn flush(&mut self) -> std::io::Result<()> {
            Ok(())
        }
    }

    impl TraceSink for Writes {
        fn discard(&mut self) {
            self.0.clear();
        }
    }

    #[test]
    fn rows_leave_in_whole_chunks_and_the_bytes_are_those_of_one_write() {
        // Enough steps for several chunks, the QoS columns of a deadline on /obs (the
        // graph's first topic), which counts.
        let mut graph = GraphSpec::chapter();
        graph.set_qos("/obs", "deadline_ms=30").unwrap();
        assert_eq!(graph.topics[0].name, "/obs");
        let topics: TopicCounters = (0..graph.topics.len() as u64)
            .map(|i| TopicStats {
                published: 7 + i,
                offered_deadline_missed: if i == 0 { 3 } else { 0 },
                depth: 1,
                ..TopicStats::default()
            })
            .collect();
        let mut log = RunLog::new(true);
        let stream = TraceStream::new(Writes(Vec::new()), &graph, 1).unwrap();
        let mut observer = stream.observer();
        for step in 1..=5_000 {
            let r = record(step, &topics);
            observer.on_step(&r);
            log.push(r);
        }
        let writes = stream.finish().unwrap().0;
        assert!(writes.len() > 3, "{} writes", writes.len());
        // Each write ends at a row's end; all but the last are a chunk or more.
        for (i, w) in writes.iter().enumerate() {
            assert_eq!(w.last(), Some(&b'\n'), "write {i}");
            assert!(
                i + 1 == writes.len() || w.len() >= CHUNK,
                "write {i}: {}",
                w.len()
            );
        }
        assert_eq!(writes.concat(), written_at_the_end(&log.trace, &graph));
        // Told after its end, the observer writes nothing.
        observer.on_step(&record(5_001, &topics));
    }

    /// A sink that takes `room` bytes, then fails as a full disk does.
    struct Full {
        kept: Arc<Mutex<Vec<u8>>>,
        room: usize,
    }

    impl Write for Full {
        fn write(&mut self, bytes: &[u8]) -> std::io::Result<usize> {
            let mut kept = lock(&self.kept);
            let n = bytes.len().min(self.room.saturating_sub(kept.len()));
            if n == 0 {
                return Err(std::io::Error::from_raw_os_error(libc_enospc()));
            }
            kept.extend_from_slice(&bytes[..n]);
            Ok(n)
        }
        fn flush(&mut self) -> std::io::Result<()> {
            Ok(())
        }
    }

    impl TraceSink for Full {
        fn discard(&mut self) {
            lock(&self.kept).clear();
        }
    }

    /// ENOSPC on Linux.
    fn libc_enospc() -> i32 {
        28
    }

    #[test]
    fn a_full_disk_fails_the_trace_at_its_end_and_gives_its_space_back() {
        let graph = GraphSpec::chapter();
        let topics: TopicCounters = (0..graph.topics.len())
            .map(|_| TopicStats::default())
            .collect();
        let kept = Arc::new(Mutex::new(Vec::new()));
        let full = Full {
            kept: kept.clone(),
            room: CHUNK / 2,
        };
        let stream = TraceStream::new(full, &graph, 1).unwrap();
        let mut observer = stream.observer();
        for step in 1..=3_000 {
            observer.on_step(&record(step, &topics));
        }
        let e = stream.finish().err().expect("a full disk fails the trace");
        assert_eq!(e.raw_os_error(), Some(libc_enospc()), "{e}");
        assert!(lock(&kept).is_empty(), "what was written is given back");
    }
}
