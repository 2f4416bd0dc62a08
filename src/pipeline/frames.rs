//! Frame ranges `A:B` (first frame A, end B exclusive; either may be omitted).

use anyhow::{bail, Context};

/// A half-open range of frame indices [start, end).
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct FrameRange {
    /// First frame.
    pub start: usize,
    /// One past the last frame.
    pub end: usize,
}

impl FrameRange {
    /// Parse `A:B`, `A:`, `:B` or `A` (one frame) against a clip of `count` frames.
    pub fn parse(text: &str, count: usize) -> anyhow::Result<FrameRange> {
        let num = |s: &str, what: &str| -> anyhow::Result<Option<usize>> {
            let s = s.trim();
            if s.is_empty() {
                return Ok(None);
            }
            s.parse::<usize>()
                .map(Some)
                .with_context(|| format!("--frames: {what} `{s}` is not a frame number"))
        };
        let (start, end) = match text.split_once(':') {
            Some((a, b)) => (
                num(a, "start")?.unwrap_or(0),
                num(b, "end")?.unwrap_or(count),
            ),
            None => {
                let a = num(text, "frame")?.context("--frames: empty range")?;
                (a, a + 1)
            }
        };
        if start >= end {
            bail!("--frames {text}: the range is empty (start {start} ≥ end {end}); the end is exclusive");
        }
        if end > count {
            bail!("--frames {text}: the clip has {count} frames (0..{count})");
        }
        Ok(FrameRange { start, end })
    }

    /// The whole clip.
    pub fn all(count: usize) -> FrameRange {
        FrameRange {
            start: 0,
            end: count,
        }
    }

    /// Number of frames.
    pub fn len(&self) -> usize {
        self.end - self.start
    }

    /// True for an empty range.
    pub fn is_empty(&self) -> bool {
        self.end <= self.start
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ranges_parse_and_bad_ones_are_named() {
        let r = |t: &str| FrameRange::parse(t, 100);
        assert_eq!(r("10:20").unwrap(), FrameRange { start: 10, end: 20 });
        assert_eq!(r(":5").unwrap(), FrameRange { start: 0, end: 5 });
        assert_eq!(
            r("95:").unwrap(),
            FrameRange {
                start: 95,
                end: 100
            }
        );
        assert_eq!(r("7").unwrap(), FrameRange { start: 7, end: 8 });
        assert!(format!("{}", r("20:10").unwrap_err()).contains("empty"));
        assert!(format!("{}", r("0:101").unwrap_err()).contains("100 frames"));
        assert!(format!("{}", r("a:b").unwrap_err()).contains("not a frame number"));
    }
}
