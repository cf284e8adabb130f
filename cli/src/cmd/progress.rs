//! Render progress on stderr: the command line's [`RenderObserver`]. A line
//! redrawn on a terminal, or plain lines for a farm log; warnings always.

use std::io::IsTerminal;
use std::sync::Mutex;
use std::time::Instant;

use throng::render::job::{RenderObserver, RenderProgress};

/// How progress is shown (`--progress`).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub enum ProgressStyle {
    /// `Bar` on a terminal, `Plain` otherwise (a farm log).
    #[default]
    Auto,
    /// One line redrawn in place.
    Bar,
    /// One line per finished layer-frame, and per block of tiles on long
    /// frames, each with percent done and ETA: for logs.
    Plain,
    /// Nothing but warnings.
    Off,
}

/// Seconds between plain lines within one layer-frame.
const PLAIN_EVERY_S: f64 = 10.0;

/// Prints a job's progress and warnings on stderr.
pub struct Progress {
    style: ProgressStyle,
    start: Instant,
    /// When the last plain line mid-frame was printed.
    last_line: Mutex<Instant>,
}

impl Progress {
    /// Progress in `style` (`Auto` decided now, from whether stderr is a terminal).
    pub fn new(style: ProgressStyle) -> Progress {
        let style = match style {
            ProgressStyle::Auto if std::io::stderr().is_terminal() => ProgressStyle::Bar,
            ProgressStyle::Auto => ProgressStyle::Plain,
            s => s,
        };
        Progress { style, start: Instant::now(), last_line: Mutex::new(Instant::now()) }
    }

    fn figures(&self, at: RenderProgress<'_>, frac: f64) -> (f64, f64, f64) {
        let progress = (at.done as f64 + frac) / at.total.max(1) as f64;
        let elapsed = self.start.elapsed().as_secs_f64();
        let eta = if progress > 0.0 { elapsed / progress - elapsed } else { 0.0 };
        (progress, elapsed, eta)
    }

    fn bar(&self, at: RenderProgress<'_>, frac: f64) {
        let (progress, elapsed, eta) = self.figures(at, frac);
        eprint!(
            "\r\x1b[2Kframe {} layer {:<8} [{}/{}] {:>5.1}%  elapsed {:.0}s  ETA {:.0}s",
            at.frame,
            at.layer,
            at.done + 1,
            at.total,
            progress * 100.0,
            elapsed,
            eta
        );
    }

    /// Ends the bar's line, so what follows starts on its own.
    pub fn finish(&self) {
        if self.style == ProgressStyle::Bar {
            eprintln!();
        }
    }
}

impl RenderObserver for Progress {
    fn wants_pixels(&self) -> bool {
        self.style != ProgressStyle::Off
    }
    fn layer_started(&self, at: RenderProgress<'_>) {
        if self.style == ProgressStyle::Bar {
            self.bar(at, 0.0);
        }
    }
    fn pixels(&self, at: RenderProgress<'_>, frac: f64) {
        match self.style {
            ProgressStyle::Bar => self.bar(at, frac),
            ProgressStyle::Plain if frac > 0.0 => {
                // A block of tiles: at most one line per PLAIN_EVERY_S, so long frames show life in a log.
                let Ok(mut last) = self.last_line.lock() else { return };
                if last.elapsed().as_secs_f64() >= PLAIN_EVERY_S {
                    *last = Instant::now();
                    let (progress, elapsed, eta) = self.figures(at, frac);
                    eprintln!(
                        "render: frame {} layer {} {:.0}% of frame; {:.1}% done, elapsed {elapsed:.0}s, ETA {eta:.0}s",
                        at.frame,
                        at.layer,
                        frac * 100.0,
                        progress * 100.0
                    );
                }
            }
            _ => {}
        }
    }
    fn layer_finished(&self, at: RenderProgress<'_>, skipped: bool) {
        if self.style != ProgressStyle::Plain {
            return;
        }
        let done = at.done + 1;
        let (progress, elapsed, eta) = self.figures(RenderProgress { done, ..at }, 0.0);
        let what = if skipped { "complete, skipped" } else { "done" };
        eprintln!(
            "render: frame {} layer {} {what} [{done}/{}] {:.1}%, elapsed {elapsed:.0}s, ETA {eta:.0}s",
            at.frame,
            at.layer,
            at.total,
            progress * 100.0
        );
        if let Ok(mut last) = self.last_line.lock() {
            *last = Instant::now();
        }
    }
    fn warning(&self, text: &str) -> throng::error::Result<()> {
        if self.style == ProgressStyle::Bar {
            eprintln!();
        }
        super::warn(&text)
    }
}
