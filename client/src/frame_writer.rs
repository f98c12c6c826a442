//! Writes frames to disk (`--dump-to`, `--png`) on a thread of its own,
//! so that the disk never holds up a vsync or the receiving loop.
//!
//! A dump commits every frame to stable storage before its manifest counts
//! it (the EXR, its metadata and the manifest are each synced, and so are
//! the directory entries), which on a real disk costs tens of milliseconds
//! per frame. Written inline, that held the presenter up by as much per
//! slot: a clean CI machine showed 53 ms between presents of a 75 Hz
//! display and not one generated frame. Here the presenter hands each
//! frame over and goes on; the queue is bounded in bytes, and when the
//! disk falls that far behind the presenter waits for it rather than drop
//! a frame (nothing presented is lost), and says so once.
//!
//! The writer also runs at a lower CPU priority
//! ([`crate::priority::BACKGROUND_NICE`]): `exr`
//! compresses each file on a thread pool of its own as wide as the machine,
//! which on a 16-core H200 machine took 78 of 481 vsyncs from a 640×360
//! presenter writing a dump (none without), and the pool's threads inherit
//! the writer thread's priority, so compression takes the cycles the
//! presenter, the decoder and an in-process server leave.

use std::path::{Path, PathBuf};
use std::sync::mpsc::{Receiver, SyncSender, TrySendError, sync_channel};
use std::thread::JoinHandle;

use anyhow::Context;
use protocol::dump::DumpWriter;
use protocol::{Frame, FrameSize};

/// Bytes of presented frames that may wait for the disk.
pub const QUEUE_BYTES: u64 = 256 << 20;

/// Where presented frames go.
pub trait FrameSink: Send {
    /// Writes a frame (the presenter numbers shown frames by display id).
    fn write(&mut self, frame: &Frame) -> anyhow::Result<()>;
    /// Called once after the last frame.
    fn finish(self: Box<Self>) -> anyhow::Result<()>;
}

/// A dump.
pub struct DumpSink(pub DumpWriter);

impl FrameSink for DumpSink {
    fn write(&mut self, frame: &Frame) -> anyhow::Result<()> {
        self.0.write_frame(frame)?;
        Ok(())
    }

    fn finish(self: Box<Self>) -> anyhow::Result<()> {
        self.0.finish()?;
        Ok(())
    }
}

/// Display-encoded PNGs, `NNNNNN.png` by frame index.
pub struct PngSink(PathBuf);

impl PngSink {
    /// Creates `dir` if needed.
    pub fn create(dir: &Path) -> anyhow::Result<Self> {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
        Ok(Self(dir.to_path_buf()))
    }
}

impl FrameSink for PngSink {
    fn write(&mut self, frame: &Frame) -> anyhow::Result<()> {
        let size = frame.meta.size;
        let image = framegen::display_encode(size.width, size.height, &frame.color)
            .ok_or_else(|| anyhow::anyhow!("frame buffers do not match its size"))?;
        image::save_buffer(
            self.0.join(format!("{:06}.png", frame.meta.index)),
            &image.to_rgb8(),
            size.width,
            size.height,
            image::ExtendedColorType::Rgb8,
        )?;
        Ok(())
    }

    fn finish(self: Box<Self>) -> anyhow::Result<()> {
        Ok(())
    }
}

/// The writing thread and the queue to it.
pub struct FrameWriter {
    queue: Option<SyncSender<Frame>>,
    thread: Option<JoinHandle<anyhow::Result<()>>>,
    waited: bool,
    /// What waits when the queue is full (named in the warning).
    waiter: &'static str,
}

impl FrameWriter {
    /// Starts a thread that writes every frame to each of `sinks` in turn,
    /// with room for `capacity` frames waiting (at least one). `waiter`
    /// names what waits when the queue is full ("presentation",
    /// "reception"), for the warning that says so.
    pub fn start(
        sinks: Vec<Box<dyn FrameSink>>,
        capacity: usize,
        waiter: &'static str,
    ) -> anyhow::Result<Self> {
        let (queue, frames) = sync_channel(capacity.max(1));
        let thread = std::thread::Builder::new()
            .name("frame-writer".into())
            .spawn(move || write_all(sinks, frames))
            .context("starting the frame writer")?;
        Ok(Self {
            queue: Some(queue),
            thread: Some(thread),
            waited: false,
            waiter,
        })
    }

    /// Room for [`QUEUE_BYTES`] of frames of `size` (a [`Frame`]'s
    /// colour, depth and motion: 20 bytes a pixel).
    pub fn capacity_for(size: FrameSize) -> usize {
        use std::mem::size_of;
        let pixel = size_of::<[half::f16; 4]>() + size_of::<f32>() + size_of::<[f32; 2]>();
        let frame = (size.pixels() * pixel as u64).max(1);
        usize::try_from(QUEUE_BYTES / frame).unwrap_or(usize::MAX)
    }

    /// Hands a frame over. Waits only when the queue is full; an error is
    /// the writer's (a full disk, say), returned at the first frame after
    /// it.
    pub fn write(&mut self, frame: Frame) -> anyhow::Result<()> {
        let Some(queue) = &self.queue else {
            anyhow::bail!("the frame writer has finished");
        };
        let item = match queue.try_send(frame) {
            Ok(()) => return Ok(()),
            Err(TrySendError::Full(item)) => item,
            Err(TrySendError::Disconnected(_)) => return Err(self.stop()),
        };
        if !self.waited {
            self.waited = true;
            tracing::warn!(
                "the disk is slower than frames arrive: {} waits for the frame writer",
                self.waiter
            );
        }
        match queue.send(item) {
            Ok(()) => Ok(()),
            Err(_) => Err(self.stop()),
        }
    }

    /// Waits until every frame is written and the sinks are finished.
    pub fn finish(mut self) -> anyhow::Result<()> {
        self.queue = None;
        self.join()
    }

    fn join(&mut self) -> anyhow::Result<()> {
        match self.thread.take().map(JoinHandle::join) {
            Some(Ok(result)) => result,
            Some(Err(_)) => Err(anyhow::anyhow!("the frame writer panicked")),
            None => Ok(()),
        }
    }

    /// The writer's error after it stopped taking frames.
    fn stop(&mut self) -> anyhow::Error {
        self.queue = None;
        match self.join() {
            Err(e) => e.context("writing presented frames"),
            Ok(()) => anyhow::anyhow!("the frame writer stopped"),
        }
    }
}

impl Drop for FrameWriter {
    /// The frames already handed over are still written (each dump frame is
    /// committed as it is written, so an early exit leaves a valid dump).
    fn drop(&mut self) {
        self.queue = None;
        if let Err(e) = self.join() {
            tracing::error!("writing presented frames: {e:#}");
        }
    }
}

fn write_all(mut sinks: Vec<Box<dyn FrameSink>>, frames: Receiver<Frame>) -> anyhow::Result<()> {
    crate::priority::lower_this_thread("the frame writer");
    for frame in frames {
        for sink in &mut sinks {
            sink.write(&frame)?;
        }
    }
    for sink in sinks {
        sink.finish()?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use std::sync::mpsc::{Sender, channel};
    use std::sync::{Arc, Barrier, Mutex};

    use super::*;

    const SIZE: FrameSize = FrameSize::new(4, 2);

    /// Records display ids; the first write waits at a barrier (a stalled
    /// disk); fails at `fail_at` if set.
    struct Probe {
        seen: Arc<Mutex<Vec<u64>>>,
        stall: Option<Arc<Barrier>>,
        fail_at: Option<u64>,
        finished: Sender<()>,
    }

    impl FrameSink for Probe {
        fn write(&mut self, frame: &Frame) -> anyhow::Result<()> {
            let display_id = frame.meta.index;
            if let Some(b) = self.stall.take() {
                b.wait();
            }
            if self.fail_at == Some(display_id) {
                anyhow::bail!("disk full");
            }
            self.seen.lock().unwrap().push(display_id);
            Ok(())
        }

        fn finish(self: Box<Self>) -> anyhow::Result<()> {
            self.finished.send(()).unwrap();
            Ok(())
        }
    }

    fn probe(stall: Option<Arc<Barrier>>, fail_at: Option<u64>) -> (Probe, Arc<Mutex<Vec<u64>>>) {
        let seen = Arc::new(Mutex::new(Vec::new()));
        let (finished, _) = channel();
        let p = Probe {
            seen: seen.clone(),
            stall,
            fail_at,
            finished,
        };
        (p, seen)
    }

    #[test]
    fn a_stalled_sink_does_not_hold_up_the_presenter_and_nothing_is_lost() {
        let stall = Arc::new(Barrier::new(2));
        let (p, seen) = probe(Some(stall.clone()), None);
        let (finished, done) = channel();
        let p = Probe { finished, ..p };
        let mut w = FrameWriter::start(vec![Box::new(p)], 8, "the test").unwrap();
        // The sink is stuck on frame 0 (or about to be): the queue takes 8
        // frames without waiting.
        for id in 0..8 {
            w.write(Frame::blank(id, SIZE)).unwrap();
        }
        assert!(seen.lock().unwrap().is_empty());
        assert!(!w.waited);
        stall.wait();
        w.write(Frame::blank(8, SIZE)).unwrap();
        w.write(Frame::blank(9, SIZE)).unwrap();
        w.finish().unwrap();
        assert_eq!(*seen.lock().unwrap(), (0..10).collect::<Vec<_>>());
        done.try_recv().expect("the sink was finished");
    }

    #[test]
    fn a_failing_sink_is_reported_at_the_next_write_or_at_the_finish() {
        let (p, seen) = probe(None, Some(2));
        let mut w = FrameWriter::start(vec![Box::new(p)], 1, "the test").unwrap();
        let mut error = None;
        for id in 0..50 {
            if let Err(e) = w.write(Frame::blank(id, SIZE)) {
                error = Some(e);
                break;
            }
        }
        let e = match error {
            Some(e) => e,
            None => w.finish().unwrap_err(),
        };
        assert!(format!("{e:#}").contains("disk full"), "{e:#}");
        assert_eq!(*seen.lock().unwrap(), vec![0, 1]);
    }

    #[test]
    fn a_dump_sink_numbers_frames_by_display_id() {
        let dir = tempfile::tempdir().unwrap();
        let manifest = protocol::dump::Manifest::new(60.0, SIZE, "t");
        let dump = DumpWriter::create(dir.path(), manifest).unwrap();
        let mut w = FrameWriter::start(vec![Box::new(DumpSink(dump))], 2, "the test").unwrap();
        for id in [0, 1, 3] {
            w.write(Frame::blank(id, SIZE)).unwrap();
        }
        w.finish().unwrap();
        let r = protocol::dump::DumpReader::open(dir.path()).unwrap();
        assert_eq!(r.len(), 3);
        assert_eq!(r.read_frame(2).unwrap().meta.index, 3);
    }

    #[test]
    fn the_queue_holds_a_quarter_gigabyte() {
        assert_eq!(
            FrameWriter::capacity_for(FrameSize::new(1280, 720)) as u64,
            QUEUE_BYTES / (1280 * 720 * 20)
        );
        assert!(FrameWriter::capacity_for(FrameSize::new(160, 90)) > 900);
    }
}
