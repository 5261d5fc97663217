//! CAPTURE: single images (PNG or JPEG) and video recording (MJPEG) of a stream's
//! output.
//!
//! The frame thread only copies the pixels and hands them to a writer thread over a
//! bounded channel ([`QUEUE_DEPTH`] jobs, `try_send`): it never waits for encoding or
//! the disk. When the queue is full the image or video frame is refused with
//! [`CaptureError::Busy`].
//!
//! - Images are encoded to `{name}.part` and renamed when complete, so a failed write
//!   leaves no half file.
//! - Videos are **MJPEG**: the file (`.mjpeg`) is the JPEG frames back to back, each a
//!   complete JFIF image (SOI … EOI) of the same size. It has no container, so no frame
//!   rate: play it with `ffplay -f mjpeg -framerate 30 file.mjpeg` / `ffmpeg -f mjpeg
//!   -framerate 30 -i file.mjpeg out.mp4`, or VLC (which detects MJPEG by the
//!   extension). [`Capturer::stop_video`] waits until the file is flushed and closed.
//! - [`Capturer::counts`] are the files completed. A write that fails does not count;
//!   its error is logged, the recording (if it was the video) ends, and the error is
//!   returned by the next call of [`Capturer::image`], [`Capturer::start_video`],
//!   [`Capturer::video_frame`], [`Capturer::stop_video`] or [`Capturer::flush`]
//!   (that call does nothing else), or taken with [`Capturer::take_error`].

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, AtomicU16, Ordering};
use std::sync::mpsc::{self, Receiver, SyncSender, TrySendError};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;

/// Jobs waiting for the writer thread at most (each holds one frame's pixels).
pub const QUEUE_DEPTH: usize = 4;

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ImageFormat {
    Png,
    Jpeg,
}

impl ImageFormat {
    pub fn extension(self) -> &'static str {
        match self {
            ImageFormat::Png => "png",
            ImageFormat::Jpeg => "jpg",
        }
    }
}

#[derive(Debug, thiserror::Error)]
pub enum CaptureError {
    #[error("{0}")]
    Io(#[from] std::io::Error),
    #[error("{0}")]
    Encode(String),
    #[error("the recorder is behind; frame dropped")]
    Busy,
    /// The pixels handed in do not describe an image.
    #[error("bad image buffer: {0}")]
    Buffer(String),
    /// An earlier write on the writer thread failed (this call did nothing).
    #[error("an earlier capture failed: {0}")]
    Earlier(String),
    #[error("not recording")]
    NotRecording,
    #[error("the capture writer thread is gone")]
    WriterGone,
}

/// One job for the writer thread.
enum Job {
    Image {
        path: PathBuf,
        format: ImageFormat,
        pixels: Vec<u8>,
        width: u32,
        height: u32,
    },
    VideoStart {
        path: PathBuf,
    },
    VideoFrame {
        pixels: Vec<u8>,
        width: u32,
        height: u32,
    },
    /// Closes the video (if any) and answers when done.
    VideoStop {
        done: mpsc::Sender<()>,
    },
    /// Answers when every earlier job is done.
    Flush {
        done: mpsc::Sender<()>,
    },
}

/// What the writer thread shares with the capturer.
#[derive(Debug, Default)]
struct Shared {
    images: AtomicU16,
    videos: AtomicU16,
    /// The recording ended on the writer side (a write failed).
    video_failed: AtomicBool,
    error: Mutex<Option<String>>,
}

impl Shared {
    fn fail(&self, what: &str, path: &Path, e: &dyn std::fmt::Display) {
        let message = format!("{what} {}: {e}", path.display());
        tracing::warn!(path = %path.display(), error = %e, "{what} failed");
        if let Ok(mut slot) = self.error.lock() {
            slot.get_or_insert(message);
        }
    }
}

/// Writes images and videos of one stream into a directory, off the frame thread.
#[derive(Debug)]
pub struct Capturer {
    dir: PathBuf,
    stream: String,
    format: ImageFormat,
    jpeg_quality: u8,
    /// Files named so far (the `{n}` of the names).
    named: u64,
    recording: bool,
    /// The recording's file.
    video_path: Option<PathBuf>,
    /// Size of the recording's frames, fixed by its first frame.
    video_size: Option<(u32, u32)>,
    jobs: Option<SyncSender<Job>>,
    writer: Option<JoinHandle<()>>,
    shared: Arc<Shared>,
}

impl Capturer {
    /// `dir` is created if missing; files are named `{stream}-{unix time}-{n}.{ext}`
    /// (the stream name reduced to letters, digits, `-` and `_`).
    pub fn new(
        dir: &Path,
        stream: &str,
        format: ImageFormat,
        jpeg_quality: u8,
    ) -> Result<Capturer, CaptureError> {
        std::fs::create_dir_all(dir)?;
        if !std::fs::metadata(dir)?.is_dir() {
            return Err(CaptureError::Io(std::io::Error::other(format!(
                "{} is not a directory",
                dir.display()
            ))));
        }
        let jpeg_quality = jpeg_quality.clamp(1, 100);
        let shared = Arc::new(Shared::default());
        let (jobs, rx) = mpsc::sync_channel(QUEUE_DEPTH);
        let writer_shared = Arc::clone(&shared);
        let writer = std::thread::Builder::new()
            .name(format!("capture-{stream}"))
            .spawn(move || write_loop(&rx, &writer_shared, jpeg_quality))?;
        let mut clean: String = stream
            .chars()
            .map(|c| {
                if c.is_ascii_alphanumeric() || c == '-' || c == '_' {
                    c
                } else {
                    '_'
                }
            })
            .collect();
        if clean.is_empty() {
            clean = "stream".into();
        }
        Ok(Capturer {
            dir: dir.to_path_buf(),
            stream: clean,
            format,
            jpeg_quality,
            named: 0,
            recording: false,
            video_path: None,
            video_size: None,
            jobs: Some(jobs),
            writer: Some(writer),
            shared,
        })
    }

    /// Saves one RGB24 image (copied; encoded on the writer thread). Returns the path it will have.
    pub fn image(
        &mut self,
        rgb: &[u8],
        width: u32,
        height: u32,
        stride: u32,
    ) -> Result<PathBuf, CaptureError> {
        self.check_error()?;
        let pixels = pack(rgb, width, height, stride, self.format)?;
        let path = self.next_path(self.format.extension());
        self.send(Job::Image {
            path: path.clone(),
            format: self.format,
            pixels,
            width,
            height,
        })?;
        Ok(path)
    }

    /// Starts a recording (no-op if one runs). Returns the file.
    pub fn start_video(&mut self) -> Result<PathBuf, CaptureError> {
        self.check_error()?;
        if let Some(path) = self.current_video() {
            return Ok(path);
        }
        let path = self.next_path("mjpeg");
        // Cleared before the writer can see the job (it sets it if the file fails).
        self.shared.video_failed.store(false, Ordering::SeqCst);
        self.send(Job::VideoStart { path: path.clone() })?;
        self.recording = true;
        self.video_size = None;
        self.video_path = Some(path.clone());
        Ok(path)
    }

    /// Stops it; the file is complete when this returns.
    pub fn stop_video(&mut self) -> Result<(), CaptureError> {
        let was = self.recording;
        self.recording = false;
        self.video_path = None;
        if was {
            let (done, wait) = mpsc::channel();
            self.jobs
                .as_ref()
                .ok_or(CaptureError::WriterGone)?
                .send(Job::VideoStop { done })
                .map_err(|_| CaptureError::WriterGone)?;
            wait.recv().map_err(|_| CaptureError::WriterGone)?;
        }
        self.check_error()
    }

    pub fn recording(&self) -> bool {
        self.recording && !self.shared.video_failed.load(Ordering::SeqCst)
    }

    /// Hands one output frame to the recording (dropped with `Busy` if the encoder is behind).
    pub fn video_frame(
        &mut self,
        rgb: &[u8],
        width: u32,
        height: u32,
        stride: u32,
    ) -> Result<(), CaptureError> {
        self.check_error()?;
        if !self.recording() {
            self.recording = false;
            return Err(CaptureError::NotRecording);
        }
        match self.video_size {
            Some(size) if size != (width, height) => {
                return Err(CaptureError::Buffer(format!(
                    "frame {width}x{height} in a {}x{} recording",
                    size.0, size.1
                )))
            }
            _ => {}
        }
        let pixels = pack(rgb, width, height, stride, ImageFormat::Jpeg)?;
        self.send(Job::VideoFrame {
            pixels,
            width,
            height,
        })?;
        self.video_size = Some((width, height));
        Ok(())
    }

    /// Images and videos completed (written to disk) so far.
    pub fn counts(&self) -> (u16, u16) {
        (
            self.shared.images.load(Ordering::SeqCst),
            self.shared.videos.load(Ordering::SeqCst),
        )
    }

    /// Waits until every job handed in so far is written (tests, shutdown); returns a
    /// failure among them.
    pub fn flush(&mut self) -> Result<(), CaptureError> {
        let (done, wait) = mpsc::channel();
        self.jobs
            .as_ref()
            .ok_or(CaptureError::WriterGone)?
            .send(Job::Flush { done })
            .map_err(|_| CaptureError::WriterGone)?;
        wait.recv().map_err(|_| CaptureError::WriterGone)?;
        self.check_error()
    }

    /// The pending error of a failed write, if any (clears it).
    pub fn take_error(&mut self) -> Option<CaptureError> {
        self.check_error().err()
    }

    /// The directory files go to.
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// JPEG quality in use (1–100).
    pub fn jpeg_quality(&self) -> u8 {
        self.jpeg_quality
    }

    fn current_video(&self) -> Option<PathBuf> {
        if self.recording() {
            self.video_path.clone()
        } else {
            None
        }
    }

    fn check_error(&mut self) -> Result<(), CaptureError> {
        let taken = self.shared.error.lock().ok().and_then(|mut e| e.take());
        match taken {
            Some(message) => Err(CaptureError::Earlier(message)),
            None => Ok(()),
        }
    }

    fn next_path(&mut self, ext: &str) -> PathBuf {
        let unix = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| d.as_secs());
        let n = self.named;
        self.named += 1;
        self.dir.join(format!("{}-{unix}-{n}.{ext}", self.stream))
    }

    fn send(&mut self, job: Job) -> Result<(), CaptureError> {
        let jobs = self.jobs.as_ref().ok_or(CaptureError::WriterGone)?;
        match jobs.try_send(job) {
            Ok(()) => Ok(()),
            Err(TrySendError::Full(_)) => Err(CaptureError::Busy),
            Err(TrySendError::Disconnected(_)) => Err(CaptureError::WriterGone),
        }
    }
}

impl Drop for Capturer {
    /// Finishes what was handed in (a running video is closed), then ends the thread.
    fn drop(&mut self) {
        drop(self.jobs.take());
        if let Some(writer) = self.writer.take() {
            let _ = writer.join();
        }
    }
}

/// Packs `rgb` rows (`stride` apart) into `width × 3` rows.
fn pack(
    rgb: &[u8],
    width: u32,
    height: u32,
    stride: u32,
    format: ImageFormat,
) -> Result<Vec<u8>, CaptureError> {
    if width == 0 || height == 0 {
        return Err(CaptureError::Buffer(format!("size {width}x{height}")));
    }
    if format == ImageFormat::Jpeg && (width > u32::from(u16::MAX) || height > u32::from(u16::MAX))
    {
        return Err(CaptureError::Buffer(format!(
            "{width}x{height} is too large for JPEG"
        )));
    }
    let (w, h, stride) = (width as usize, height as usize, stride as usize);
    let row = w * 3;
    if stride < row {
        return Err(CaptureError::Buffer(format!(
            "stride {stride} < {row} bytes of a row"
        )));
    }
    let needed = stride * (h - 1) + row;
    if rgb.len() < needed {
        return Err(CaptureError::Buffer(format!(
            "{} bytes, {width}x{height} stride {stride} needs {needed}",
            rgb.len()
        )));
    }
    let mut out = Vec::with_capacity(row * h);
    for y in 0..h {
        out.extend_from_slice(&rgb[y * stride..y * stride + row]);
    }
    Ok(out)
}

/// The writer thread: runs until the capturer is dropped.
fn write_loop(jobs: &Receiver<Job>, shared: &Shared, quality: u8) {
    let mut video: Option<(PathBuf, BufWriter<File>)> = None;
    let mut frame = Vec::new();
    for job in jobs {
        match job {
            Job::Image {
                path,
                format,
                pixels,
                width,
                height,
            } => match write_image(&path, format, &pixels, width, height, quality) {
                Ok(()) => {
                    shared.images.fetch_add(1, Ordering::SeqCst);
                    tracing::info!(path = %path.display(), "image captured");
                }
                Err(e) => shared.fail("image", &path, &e),
            },
            Job::VideoStart { path } => {
                if let Some((old, file)) = video.take() {
                    finish_video(shared, old, file);
                }
                match File::create(&path) {
                    Ok(file) => {
                        tracing::info!(path = %path.display(), "recording started");
                        video = Some((path, BufWriter::new(file)));
                    }
                    Err(e) => {
                        shared.video_failed.store(true, Ordering::SeqCst);
                        shared.fail("video", &path, &e);
                    }
                }
            }
            Job::VideoFrame {
                pixels,
                width,
                height,
            } => {
                let Some((path, file)) = video.as_mut() else {
                    continue;
                };
                frame.clear();
                let written = encode_jpeg(&mut frame, &pixels, width, height, quality)
                    .and_then(|()| file.write_all(&frame).map_err(CaptureError::Io));
                if let Err(e) = written {
                    shared.video_failed.store(true, Ordering::SeqCst);
                    shared.fail("video", path, &e);
                    video = None;
                }
            }
            Job::VideoStop { done } => {
                if let Some((path, file)) = video.take() {
                    finish_video(shared, path, file);
                }
                let _ = done.send(());
            }
            Job::Flush { done } => {
                let _ = done.send(());
            }
        }
    }
    if let Some((path, file)) = video.take() {
        finish_video(shared, path, file);
    }
}

fn finish_video(shared: &Shared, path: PathBuf, mut file: BufWriter<File>) {
    let closed = file.flush().and_then(|()| {
        file.into_inner()
            .map_err(|e| e.into_error())
            .and_then(|f| f.sync_data())
    });
    match closed {
        Ok(()) => {
            shared.videos.fetch_add(1, Ordering::SeqCst);
            tracing::info!(path = %path.display(), "recording complete");
        }
        Err(e) => shared.fail("video", &path, &e),
    }
}

fn encode_jpeg(
    out: &mut Vec<u8>,
    pixels: &[u8],
    width: u32,
    height: u32,
    quality: u8,
) -> Result<(), CaptureError> {
    let (w, h) = (
        u16::try_from(width).map_err(|_| CaptureError::Encode("width".into()))?,
        u16::try_from(height).map_err(|_| CaptureError::Encode("height".into()))?,
    );
    jpeg_encoder::Encoder::new(out, quality)
        .encode(pixels, w, h, jpeg_encoder::ColorType::Rgb)
        .map_err(|e| CaptureError::Encode(format!("jpeg: {e}")))
}

fn write_image(
    path: &Path,
    format: ImageFormat,
    pixels: &[u8],
    width: u32,
    height: u32,
    quality: u8,
) -> Result<(), CaptureError> {
    let part = path.with_extension(format!("{}.part", format.extension()));
    let result = (|| {
        let mut file = BufWriter::new(File::create(&part)?);
        if format == ImageFormat::Png {
            let mut encoder = png::Encoder::new(&mut file, width, height);
            encoder.set_color(png::ColorType::Rgb);
            encoder.set_depth(png::BitDepth::Eight);
            let mut writer = encoder
                .write_header()
                .map_err(|e| CaptureError::Encode(format!("png: {e}")))?;
            writer
                .write_image_data(pixels)
                .map_err(|e| CaptureError::Encode(format!("png: {e}")))?;
            writer
                .finish()
                .map_err(|e| CaptureError::Encode(format!("png: {e}")))?;
        } else {
            let mut bytes = Vec::new();
            encode_jpeg(&mut bytes, pixels, width, height, quality)?;
            file.write_all(&bytes)?;
        }
        file.flush()?;
        drop(file);
        std::fs::rename(&part, path)?;
        Ok(())
    })();
    if result.is_err() {
        let _ = std::fs::remove_file(&part);
    }
    result
}

#[cfg(test)]
mod tests {
    use super::*;

    fn gradient(w: u32, h: u32, stride: u32) -> Vec<u8> {
        let mut v = vec![0u8; (stride * h) as usize];
        for y in 0..h {
            for x in 0..w {
                let at = (y * stride + x * 3) as usize;
                v[at] = (x * 7 % 256) as u8;
                v[at + 1] = (y * 5 % 256) as u8;
                v[at + 2] = ((x + y) % 256) as u8;
            }
        }
        v
    }

    /// (width, height) from a JPEG's SOF0 segment.
    fn jpeg_size(bytes: &[u8]) -> Option<(u16, u16)> {
        let mut i = 2;
        while i + 9 < bytes.len() {
            if bytes[i] != 0xFF {
                return None;
            }
            let marker = bytes[i + 1];
            let len = usize::from(u16::from_be_bytes([bytes[i + 2], bytes[i + 3]]));
            if (0xC0..=0xC2).contains(&marker) {
                let h = u16::from_be_bytes([bytes[i + 5], bytes[i + 6]]);
                let w = u16::from_be_bytes([bytes[i + 7], bytes[i + 8]]);
                return Some((w, h));
            }
            i += 2 + len;
        }
        None
    }

    #[test]
    fn png_decodes_back_to_the_pixels() {
        let dir = tempfile::tempdir().unwrap();
        let mut c = Capturer::new(
            &dir.path().join("new/sub"),
            "main/../x",
            ImageFormat::Png,
            90,
        )
        .unwrap();
        let (w, h, stride) = (37u32, 21u32, 37 * 3 + 5);
        let rgb = gradient(w, h, stride);
        let path = c.image(&rgb, w, h, stride).unwrap();
        assert!(path.starts_with(dir.path().join("new/sub")));
        let name = path.file_name().unwrap().to_str().unwrap().to_owned();
        assert!(
            name.starts_with("main____x-") && name.ends_with("-0.png"),
            "{name}"
        );
        c.flush().unwrap();
        assert_eq!(c.counts(), (1, 0));
        let decoder = png::Decoder::new(File::open(&path).unwrap());
        let mut reader = decoder.read_info().unwrap();
        let mut buf = vec![0; reader.output_buffer_size()];
        let info = reader.next_frame(&mut buf).unwrap();
        assert_eq!((info.width, info.height), (w, h));
        assert_eq!(info.color_type, png::ColorType::Rgb);
        for y in 0..h as usize {
            let row = &buf[y * w as usize * 3..(y + 1) * w as usize * 3];
            assert_eq!(
                row,
                &rgb[y * stride as usize..y * stride as usize + w as usize * 3]
            );
        }
        // No leftover partial file.
        let files: Vec<_> = std::fs::read_dir(dir.path().join("new/sub"))
            .unwrap()
            .collect();
        assert_eq!(files.len(), 1);
    }

    #[test]
    fn jpeg_has_soi_and_the_size_in_sof() {
        let dir = tempfile::tempdir().unwrap();
        let mut c = Capturer::new(dir.path(), "main", ImageFormat::Jpeg, 85).unwrap();
        let rgb = gradient(64, 40, 64 * 3);
        let path = c.image(&rgb, 64, 40, 64 * 3).unwrap();
        assert_eq!(path.extension().unwrap(), "jpg");
        c.flush().unwrap();
        let bytes = std::fs::read(&path).unwrap();
        assert_eq!(&bytes[..2], &[0xFF, 0xD8]);
        assert_eq!(&bytes[bytes.len() - 2..], &[0xFF, 0xD9]);
        assert_eq!(jpeg_size(&bytes), Some((64, 40)));
        assert_eq!(c.counts(), (1, 0));
    }

    #[test]
    fn a_ten_frame_video_has_ten_jpegs() {
        let dir = tempfile::tempdir().unwrap();
        let mut c = Capturer::new(dir.path(), "main", ImageFormat::Png, 80).unwrap();
        assert!(matches!(
            c.video_frame(&[0; 12], 2, 2, 6),
            Err(CaptureError::NotRecording)
        ));
        let path = c.start_video().unwrap();
        assert!(c.recording());
        // Already recording: the same file.
        assert_eq!(c.start_video().unwrap(), path);
        let rgb = gradient(32, 24, 32 * 3);
        let mut sent = 0;
        while sent < 10 {
            match c.video_frame(&rgb, 32, 24, 32 * 3) {
                Ok(()) => sent += 1,
                Err(CaptureError::Busy) => std::thread::yield_now(),
                Err(e) => panic!("{e}"),
            }
        }
        assert!(matches!(
            c.video_frame(&gradient(16, 16, 48), 16, 16, 48),
            Err(CaptureError::Buffer(_))
        ));
        c.stop_video().unwrap();
        assert!(!c.recording());
        assert_eq!(c.counts(), (0, 1));
        let bytes = std::fs::read(&path).unwrap();
        assert_eq!(path.extension().unwrap(), "mjpeg");
        let soi = bytes
            .windows(3)
            .filter(|w| w == &[0xFF, 0xD8, 0xFF])
            .count();
        let eoi = bytes.windows(2).filter(|w| w == &[0xFF, 0xD9]).count();
        assert_eq!(soi, 10);
        assert!(eoi >= 10);
        assert_eq!(jpeg_size(&bytes), Some((32, 24)));
        // Stopping again is harmless; a second recording is another file.
        c.stop_video().unwrap();
        let second = c.start_video().unwrap();
        assert_ne!(second, path);
        c.stop_video().unwrap();
        assert_eq!(c.counts(), (0, 2));
    }

    #[test]
    fn unwritable_places_are_errors_and_do_not_count() {
        let dir = tempfile::tempdir().unwrap();
        let file = dir.path().join("plain");
        std::fs::write(&file, b"x").unwrap();
        assert!(matches!(
            Capturer::new(&file.join("sub"), "main", ImageFormat::Png, 90),
            Err(CaptureError::Io(_))
        ));
        assert!(Capturer::new(&file, "main", ImageFormat::Png, 90).is_err());
        // The directory disappears under a running capturer.
        let gone = dir.path().join("gone");
        let mut c = Capturer::new(&gone, "main", ImageFormat::Png, 90).unwrap();
        std::fs::remove_dir(&gone).unwrap();
        c.image(&gradient(4, 4, 12), 4, 4, 12).unwrap();
        assert!(matches!(c.flush(), Err(CaptureError::Earlier(_))));
        assert_eq!(c.counts(), (0, 0));
        // The error was reported once; the next capture works again.
        std::fs::create_dir(&gone).unwrap();
        c.image(&gradient(4, 4, 12), 4, 4, 12).unwrap();
        c.flush().unwrap();
        assert_eq!(c.counts(), (1, 0));
        // A video that cannot be created ends the recording.
        std::fs::remove_dir_all(&gone).unwrap();
        c.start_video().unwrap();
        c.flush().unwrap_err();
        assert!(!c.recording());
        assert!(c.stop_video().is_ok());
        assert_eq!(c.counts(), (1, 0));
    }

    #[test]
    fn bad_buffers_are_refused() {
        let dir = tempfile::tempdir().unwrap();
        let mut c = Capturer::new(dir.path(), "main", ImageFormat::Jpeg, 0).unwrap();
        assert_eq!(c.jpeg_quality(), 1);
        assert!(matches!(
            c.image(&[0; 11], 2, 2, 6),
            Err(CaptureError::Buffer(_))
        ));
        assert!(matches!(
            c.image(&[0; 12], 2, 2, 5),
            Err(CaptureError::Buffer(_))
        ));
        assert!(matches!(
            c.image(&[], 0, 2, 6),
            Err(CaptureError::Buffer(_))
        ));
        assert!(matches!(
            c.image(&[0; 3], 70_000, 1, 210_000),
            Err(CaptureError::Buffer(_))
        ));
        c.flush().unwrap();
        assert_eq!(c.counts(), (0, 0));
    }
}
