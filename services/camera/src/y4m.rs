//! YUV4MPEG2 (`.y4m`) stream reader: pure parsing over any `BufRead`, frame by frame
//! (the file is never loaded whole).
//!
//! A stream is one header line, `YUV4MPEG2` followed by space-separated tags, then
//! frames, each a `FRAME` line (optional parameters after a space) and exactly one
//! frame of planar pixels: luma `W·H` bytes, then Cb and Cr of `⌈W/2⌉·⌈H/2⌉` bytes
//! each (4:2:0), or luma only (`Cmono`).
//!
//! Tags: `W` and `H` (required), `F` (frame rate `num:den`, optional), `C` (chroma:
//! `420jpeg` — the default when absent —, `420paldv`, `420mpeg2`, `420`, `mono`; the
//! 4:2:0 variants differ only in chroma siting, which is ignored; 4:2:2, 4:4:4 and
//! anything else are refused). `I` (interlacing), `A` (pixel aspect) and `X`
//! (extensions, e.g. `XCOLORRANGE`) are ignored; any other tag is refused.
//!
//! Hostile input: lines are length-capped before they are buffered, sizes are capped
//! and computed without overflow, and every error names the byte offset where the
//! stream stopped making sense. Nothing here panics on input.

use std::fmt;
use std::io::{self, BufRead, Seek, SeekFrom};

/// Longest header line accepted (real ones are well under 100 bytes).
pub const MAX_HEADER_LINE: usize = 1024;
/// Longest `FRAME` line accepted (with parameters).
pub const MAX_FRAME_LINE: usize = 256;
/// Largest `W` or `H` accepted by the parser (the camera's config limits are smaller).
pub const MAX_DIMENSION: u32 = 16_384;

const MAGIC: &[u8] = b"YUV4MPEG2";
const FRAME: &[u8] = b"FRAME";

/// The chroma layout of the stream's frames.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Chroma {
    /// 4:2:0: Cb and Cr planes of `⌈W/2⌉ × ⌈H/2⌉` after the luma plane.
    C420,
    /// Luma only.
    Mono,
}

/// The stream header.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Y4mHeader {
    pub width: u32,
    pub height: u32,
    /// Frame rate `(num, den)` when the header has an `F` tag.
    pub rate: Option<(u32, u32)>,
    pub chroma: Chroma,
}

impl Y4mHeader {
    /// Width and height of each chroma plane (`⌈W/2⌉`, `⌈H/2⌉`); `(0, 0)` for mono.
    pub fn chroma_size(&self) -> (usize, usize) {
        match self.chroma {
            Chroma::C420 => (
                (self.width as usize).div_ceil(2),
                (self.height as usize).div_ceil(2),
            ),
            Chroma::Mono => (0, 0),
        }
    }

    /// Bytes of pixels in one frame (after its `FRAME` line).
    pub fn frame_len(&self) -> usize {
        let (cw, ch) = self.chroma_size();
        self.width as usize * self.height as usize + 2 * cw * ch
    }

    /// The stream header line (with its newline) that describes this header; what
    /// [`Y4mReader::new`] parses back. Each frame is then `FRAME\n` and its pixels.
    pub fn line(&self) -> String {
        let mut s = format!("YUV4MPEG2 W{} H{}", self.width, self.height);
        if let Some((n, d)) = self.rate {
            s.push_str(&format!(" F{n}:{d}"));
        }
        s.push_str(match self.chroma {
            Chroma::C420 => " C420jpeg\n",
            Chroma::Mono => " Cmono\n",
        });
        s
    }

    /// The frame rate in frames per second, if the header has one.
    pub fn fps(&self) -> Option<f64> {
        self.rate.map(|(n, d)| f64::from(n) / f64::from(d))
    }
}

/// Why a stream cannot be read. Every variant names the byte offset (from the start
/// of the stream) where reading stopped.
#[derive(Debug)]
pub enum Y4mError {
    Io {
        offset: u64,
        source: io::Error,
    },
    /// The stream does not start with `YUV4MPEG2 `.
    BadMagic {
        offset: u64,
    },
    /// A header or `FRAME` line longer than its cap (or without its newline).
    LineTooLong {
        offset: u64,
        max: usize,
    },
    /// A header tag that cannot be parsed.
    BadTag {
        offset: u64,
        tag: String,
        reason: &'static str,
    },
    /// A required tag (`W`, `H`) is missing.
    MissingTag {
        offset: u64,
        tag: char,
    },
    /// A chroma layout other than 4:2:0 or mono.
    UnsupportedChroma {
        offset: u64,
        chroma: String,
    },
    /// Something other than a `FRAME` line where a frame should start.
    BadFrameLine {
        offset: u64,
    },
    /// The stream ends inside the header, a `FRAME` line or a frame's pixels.
    Truncated {
        offset: u64,
        what: &'static str,
        needed: usize,
        got: usize,
    },
    /// The caller's buffer is not one frame long.
    BufferSize {
        offset: u64,
        needed: usize,
        got: usize,
    },
}

impl Y4mError {
    /// The byte offset where reading stopped.
    pub fn offset(&self) -> u64 {
        match self {
            Y4mError::Io { offset, .. }
            | Y4mError::BadMagic { offset }
            | Y4mError::LineTooLong { offset, .. }
            | Y4mError::BadTag { offset, .. }
            | Y4mError::MissingTag { offset, .. }
            | Y4mError::UnsupportedChroma { offset, .. }
            | Y4mError::BadFrameLine { offset }
            | Y4mError::Truncated { offset, .. }
            | Y4mError::BufferSize { offset, .. } => *offset,
        }
    }
}

impl fmt::Display for Y4mError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Y4mError::Io { offset, source } => write!(f, "at byte {offset}: read error: {source}"),
            Y4mError::BadMagic { offset } => {
                write!(f, "at byte {offset}: not a YUV4MPEG2 stream (no `YUV4MPEG2 ` magic)")
            }
            Y4mError::LineTooLong { offset, max } => write!(
                f,
                "at byte {offset}: line longer than {max} bytes (or no newline)"
            ),
            Y4mError::BadTag {
                offset,
                tag,
                reason,
            } => write!(f, "at byte {offset}: header tag `{tag}`: {reason}"),
            Y4mError::MissingTag { offset, tag } => {
                write!(f, "at byte {offset}: the header has no `{tag}` tag")
            }
            Y4mError::UnsupportedChroma { offset, chroma } => write!(
                f,
                "at byte {offset}: chroma `C{chroma}` is not supported (420jpeg, 420paldv, 420mpeg2, 420, mono)"
            ),
            Y4mError::BadFrameLine { offset } => {
                write!(f, "at byte {offset}: expected a `FRAME` line")
            }
            Y4mError::Truncated {
                offset,
                what,
                needed,
                got,
            } => write!(
                f,
                "at byte {offset}: the stream ends inside {what} ({got} of {needed} bytes)"
            ),
            Y4mError::BufferSize {
                offset,
                needed,
                got,
            } => write!(
                f,
                "at byte {offset}: frame buffer of {got} bytes, a frame is {needed}"
            ),
        }
    }
}

impl std::error::Error for Y4mError {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        match self {
            Y4mError::Io { source, .. } => Some(source),
            _ => None,
        }
    }
}

/// Reads a Y4M stream frame by frame.
#[derive(Debug)]
pub struct Y4mReader<R> {
    inner: R,
    header: Y4mHeader,
    /// Bytes consumed from the start of the stream.
    pos: u64,
    /// Where the first `FRAME` line starts.
    data_start: u64,
    /// Frames read since the start (or the last rewind).
    frames: u64,
}

impl<R: BufRead> Y4mReader<R> {
    /// Reads and checks the stream header.
    pub fn new(mut inner: R) -> Result<Self, Y4mError> {
        let mut line = Vec::with_capacity(128);
        match read_line(&mut inner, 0, MAX_HEADER_LINE, &mut line)? {
            LineEnd::Newline => {}
            LineEnd::Eof => {
                return Err(if line.is_empty() {
                    Y4mError::BadMagic { offset: 0 }
                } else {
                    Y4mError::Truncated {
                        offset: line.len() as u64,
                        what: "the header line",
                        needed: line.len() + 1,
                        got: line.len(),
                    }
                })
            }
        }
        let header = parse_header(&line)?;
        let pos = line.len() as u64 + 1;
        Ok(Y4mReader {
            inner,
            header,
            pos,
            data_start: pos,
            frames: 0,
        })
    }

    pub fn header(&self) -> &Y4mHeader {
        &self.header
    }

    /// Byte offset of the next unread byte.
    pub fn position(&self) -> u64 {
        self.pos
    }

    /// Frames read since the start or the last [`Self::rewind`].
    pub fn frames_read(&self) -> u64 {
        self.frames
    }

    /// Reads the next frame's pixels into `buf` (exactly [`Y4mHeader::frame_len`]
    /// bytes): `Ok(true)` with a frame, `Ok(false)` at the end of the stream (exactly
    /// at a frame boundary); any other end is [`Y4mError::Truncated`].
    pub fn read_frame(&mut self, buf: &mut [u8]) -> Result<bool, Y4mError> {
        let needed = self.header.frame_len();
        if buf.len() != needed {
            return Err(Y4mError::BufferSize {
                offset: self.pos,
                needed,
                got: buf.len(),
            });
        }
        let start = self.pos;
        let mut line = Vec::with_capacity(16);
        let end = read_line(&mut self.inner, start, MAX_FRAME_LINE, &mut line)?;
        if end == LineEnd::Eof {
            if line.is_empty() {
                return Ok(false);
            }
            // A partial `FRAME` line (or garbage) at the end.
            if !FRAME.starts_with(&line[..line.len().min(FRAME.len())]) {
                return Err(Y4mError::BadFrameLine { offset: start });
            }
            return Err(Y4mError::Truncated {
                offset: start + line.len() as u64,
                what: "a FRAME line",
                needed: line.len() + 1,
                got: line.len(),
            });
        }
        let ok =
            line.starts_with(FRAME) && (line.len() == FRAME.len() || line[FRAME.len()] == b' ');
        if !ok {
            return Err(Y4mError::BadFrameLine { offset: start });
        }
        self.pos = start + line.len() as u64 + 1;
        let mut got = 0;
        while got < needed {
            match self.inner.read(&mut buf[got..]) {
                Ok(0) => {
                    return Err(Y4mError::Truncated {
                        offset: self.pos + got as u64,
                        what: "a frame's pixels",
                        needed,
                        got,
                    })
                }
                Ok(n) => got += n,
                Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
                Err(source) => {
                    return Err(Y4mError::Io {
                        offset: self.pos + got as u64,
                        source,
                    })
                }
            }
        }
        self.pos += needed as u64;
        self.frames += 1;
        Ok(true)
    }
}

impl<R: BufRead + Seek> Y4mReader<R> {
    /// Goes back to the first frame.
    pub fn rewind(&mut self) -> Result<(), Y4mError> {
        self.inner
            .seek(SeekFrom::Start(self.data_start))
            .map_err(|source| Y4mError::Io {
                offset: self.pos,
                source,
            })?;
        self.pos = self.data_start;
        self.frames = 0;
        Ok(())
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum LineEnd {
    Newline,
    Eof,
}

/// Reads up to and including `\n` (not stored in `out`), at most `max` bytes before
/// it; `offset` is where the line starts (for errors).
fn read_line<R: BufRead>(
    r: &mut R,
    offset: u64,
    max: usize,
    out: &mut Vec<u8>,
) -> Result<LineEnd, Y4mError> {
    loop {
        let avail = match r.fill_buf() {
            Ok(b) => b,
            Err(e) if e.kind() == io::ErrorKind::Interrupted => continue,
            Err(source) => {
                return Err(Y4mError::Io {
                    offset: offset + out.len() as u64,
                    source,
                })
            }
        };
        if avail.is_empty() {
            return Ok(LineEnd::Eof);
        }
        let room = max - out.len();
        let scan = &avail[..avail.len().min(room + 1)];
        if let Some(i) = scan.iter().position(|&b| b == b'\n') {
            out.extend_from_slice(&scan[..i]);
            r.consume(i + 1);
            return Ok(LineEnd::Newline);
        }
        if scan.len() > room {
            return Err(Y4mError::LineTooLong { offset, max });
        }
        let n = scan.len();
        out.extend_from_slice(scan);
        r.consume(n);
    }
}

fn parse_header(line: &[u8]) -> Result<Y4mHeader, Y4mError> {
    if !line.starts_with(MAGIC) || line.get(MAGIC.len()) != Some(&b' ') {
        return Err(Y4mError::BadMagic { offset: 0 });
    }
    let (mut width, mut height, mut rate) = (None, None, None);
    let mut chroma = Chroma::C420;
    let mut at = MAGIC.len() + 1;
    for token in line[MAGIC.len() + 1..].split(|&b| b == b' ') {
        let offset = at as u64;
        at += token.len() + 1;
        if token.is_empty() {
            continue;
        }
        let text = String::from_utf8_lossy(token);
        let bad = |reason| Y4mError::BadTag {
            offset,
            tag: text.chars().take(32).collect(),
            reason,
        };
        let value = &token[1..];
        match token[0] {
            b'W' | b'H' => {
                let v = parse_u32(value)
                    .filter(|v| (1..=MAX_DIMENSION).contains(v))
                    .ok_or_else(|| bad("not an integer in 1..=16384"))?;
                if token[0] == b'W' {
                    width = Some(v);
                } else {
                    height = Some(v);
                }
            }
            b'F' => {
                let mut parts = value.splitn(2, |&b| b == b':');
                let num = parts.next().and_then(parse_u32);
                let den = parts.next().and_then(parse_u32);
                match (num, den) {
                    (Some(n), Some(d)) if n > 0 && d > 0 => rate = Some((n, d)),
                    _ => return Err(bad("not a frame rate num:den of positive integers")),
                }
            }
            b'C' => {
                chroma = match value {
                    b"420jpeg" | b"420paldv" | b"420mpeg2" | b"420" => Chroma::C420,
                    b"mono" => Chroma::Mono,
                    other => {
                        return Err(Y4mError::UnsupportedChroma {
                            offset,
                            chroma: String::from_utf8_lossy(other).chars().take(32).collect(),
                        })
                    }
                }
            }
            b'I' | b'A' | b'X' => {}
            _ => return Err(bad("unknown tag")),
        }
    }
    let end = line.len() as u64;
    Ok(Y4mHeader {
        width: width.ok_or(Y4mError::MissingTag {
            offset: end,
            tag: 'W',
        })?,
        height: height.ok_or(Y4mError::MissingTag {
            offset: end,
            tag: 'H',
        })?,
        rate,
        chroma,
    })
}

fn parse_u32(digits: &[u8]) -> Option<u32> {
    if digits.is_empty() || digits.len() > 10 || !digits.iter().all(u8::is_ascii_digit) {
        return None;
    }
    std::str::from_utf8(digits).ok()?.parse().ok()
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::io::Cursor;

    fn stream(header: &str, frames: &[&[u8]]) -> Vec<u8> {
        let mut v = header.as_bytes().to_vec();
        for f in frames {
            v.extend_from_slice(b"FRAME\n");
            v.extend_from_slice(f);
        }
        v
    }

    #[test]
    fn a_header_with_every_tag_parses() {
        let line =
            b"YUV4MPEG2 W64 H48 F30000:1001 Ip A1:1 C420mpeg2 XYSCSS=420MPEG2 XCOLORRANGE=FULL\n";
        let r = Y4mReader::new(Cursor::new(line.to_vec())).unwrap();
        let h = *r.header();
        assert_eq!((h.width, h.height, h.rate), (64, 48, Some((30000, 1001))));
        assert_eq!(h.chroma, Chroma::C420);
        assert_eq!(h.frame_len(), 64 * 48 * 3 / 2);
        assert!((h.fps().unwrap() - 29.97).abs() < 0.01);
        assert_eq!(r.position(), line.len() as u64);
    }

    #[test]
    fn the_header_line_parses_back() {
        for h in [
            Y4mHeader {
                width: 64,
                height: 48,
                rate: Some((25, 1)),
                chroma: Chroma::C420,
            },
            Y4mHeader {
                width: 7,
                height: 5,
                rate: None,
                chroma: Chroma::Mono,
            },
        ] {
            let r = Y4mReader::new(Cursor::new(h.line().into_bytes())).unwrap();
            assert_eq!(*r.header(), h);
        }
    }

    #[test]
    fn odd_sizes_round_chroma_up_and_mono_has_none() {
        let odd = parse_header(b"YUV4MPEG2 W5 H3").unwrap();
        assert_eq!(odd.chroma_size(), (3, 2));
        assert_eq!(odd.frame_len(), 15 + 12);
        assert_eq!(odd.rate, None);
        let mono = parse_header(b"YUV4MPEG2 W5 H3 Cmono").unwrap();
        assert_eq!(mono.frame_len(), 15);
    }

    #[test]
    fn frames_with_and_without_parameters_then_the_end() {
        let mut data = stream("YUV4MPEG2 W2 H2 Cmono\n", &[&[1, 2, 3, 4]]);
        data.extend_from_slice(b"FRAME Ip XFOO=1\n\x05\x06\x07\x08");
        let mut r = Y4mReader::new(Cursor::new(data)).unwrap();
        let mut buf = [0u8; 4];
        assert!(r.read_frame(&mut buf).unwrap());
        assert_eq!(buf, [1, 2, 3, 4]);
        assert!(r.read_frame(&mut buf).unwrap());
        assert_eq!(buf, [5, 6, 7, 8]);
        assert!(!r.read_frame(&mut buf).unwrap());
        assert_eq!(r.frames_read(), 2);
        r.rewind().unwrap();
        assert!(r.read_frame(&mut buf).unwrap());
        assert_eq!(buf, [1, 2, 3, 4]);
    }

    #[test]
    fn bad_headers_are_refused_with_their_offset() {
        let cases: &[(&[u8], u64)] = &[
            (b"", 0),
            (b"YUV4MPEG W2 H2\n", 0),
            (b"YUV4MPEG2 W2 H2", 15),
            (b"YUV4MPEG2 W0 H2\n", 10),
            (b"YUV4MPEG2 W2 Hx\n", 13),
            (b"YUV4MPEG2 W2 H2 F30:0\n", 16),
            (b"YUV4MPEG2 W99999999999 H2\n", 10),
            (b"YUV4MPEG2 W2 H2 Q1\n", 16),
            (b"YUV4MPEG2 W2\n", 12),
            (b"YUV4MPEG2 W2 H2 C422\n", 16),
            (b"YUV4MPEG2 W2 H2 C444alpha\n", 16),
        ];
        for (input, offset) in cases {
            let e = Y4mReader::new(Cursor::new(input.to_vec())).unwrap_err();
            assert_eq!(
                e.offset(),
                *offset,
                "{:?}: {e}",
                String::from_utf8_lossy(input)
            );
            assert!(e.to_string().contains(&format!("at byte {offset}")), "{e}");
        }
        let e = Y4mReader::new(Cursor::new(b"YUV4MPEG2 W2 H2 C422\n".to_vec())).unwrap_err();
        assert!(matches!(e, Y4mError::UnsupportedChroma { ref chroma, .. } if chroma == "422"));
        assert!(e.to_string().contains("not supported"), "{e}");
        // An endless header line is refused at the cap, not buffered.
        let long = [b"YUV4MPEG2 W2 H2 ".as_slice(), &[b'X'; 5000]].concat();
        let e = Y4mReader::new(Cursor::new(long)).unwrap_err();
        assert!(matches!(e, Y4mError::LineTooLong { offset: 0, .. }), "{e}");
    }

    #[test]
    fn truncated_and_corrupt_frames_name_their_offset() {
        let header = "YUV4MPEG2 W2 H2 Cmono\n"; // 22 bytes
        let mut buf = [0u8; 4];
        // The pixels of the second frame stop after 3 of 4 bytes.
        let mut data = stream(header, &[&[1, 2, 3, 4]]);
        data.extend_from_slice(b"FRAME\n\x01\x02\x03");
        let mut r = Y4mReader::new(Cursor::new(data)).unwrap();
        assert!(r.read_frame(&mut buf).unwrap());
        let e = r.read_frame(&mut buf).unwrap_err();
        assert!(
            matches!(
                e,
                Y4mError::Truncated {
                    offset: 41,
                    needed: 4,
                    got: 3,
                    ..
                }
            ),
            "{e}"
        );
        // A partial FRAME line at the end.
        let mut data = stream(header, &[]);
        data.extend_from_slice(b"FRA");
        let e = Y4mReader::new(Cursor::new(data))
            .unwrap()
            .read_frame(&mut buf)
            .unwrap_err();
        assert!(matches!(e, Y4mError::Truncated { offset: 25, .. }), "{e}");
        // Garbage where a frame starts, and a frame line without its newline.
        for tail in [b"JUNK\n".as_slice(), b"FRAMES\n", &[b'F'; 300]] {
            let mut data = stream(header, &[]);
            data.extend_from_slice(tail);
            let e = Y4mReader::new(Cursor::new(data))
                .unwrap()
                .read_frame(&mut buf)
                .unwrap_err();
            assert_eq!(e.offset(), 22, "{e}");
        }
        // A wrong buffer is the caller's error, not a panic.
        let mut r = Y4mReader::new(Cursor::new(stream(header, &[&[0; 4]]))).unwrap();
        assert!(matches!(
            r.read_frame(&mut [0u8; 3]),
            Err(Y4mError::BufferSize {
                needed: 4,
                got: 3,
                ..
            })
        ));
    }

    #[test]
    fn every_prefix_of_a_stream_is_an_error_or_fewer_frames_never_a_panic() {
        let data = stream("YUV4MPEG2 W3 H3 F25:1\n", &[&[7; 17], &[9; 17]]);
        for cut in 0..=data.len() {
            let Ok(mut r) = Y4mReader::new(Cursor::new(data[..cut].to_vec())) else {
                continue;
            };
            let mut buf = vec![0u8; r.header().frame_len()];
            let mut n = 0;
            loop {
                match r.read_frame(&mut buf) {
                    Ok(true) => n += 1,
                    Ok(false) => break,
                    Err(e) => {
                        assert!(e.offset() <= cut as u64, "{cut}: {e}");
                        break;
                    }
                }
            }
            assert!(n <= 2);
            if cut == data.len() {
                assert_eq!(n, 2);
            }
        }
    }
}
