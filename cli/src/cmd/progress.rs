//! Render progress on stderr: the command line's [`RenderObserver`]. A line
//! redrawn on a terminal, or plain lines for a farm log; warnings always.

use std::io::IsTerminal;
use std::sync::Mutex;
use std::time::{Duration, Instant};

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

/// Least time between two redraws of the bar: at most 10 a second (each
/// tile reports, hundreds a second on a small frame; a terminal, or a
/// remote one, should not be flooded with redraws).
const BAR_EVERY: Duration = Duration::from_millis(100);

/// When the bar may be redrawn: at most once per `every`, and always for
/// the job's last update, so the bar ends showing where the job ended.
#[derive(Debug)]
struct Throttle {
    every: Duration,
    last: Option<Instant>,
}

impl Throttle {
    fn new(every: Duration) -> Throttle {
        Throttle { every, last: None }
    }

    /// Whether to draw at `now` (`last_one`: the job's final update); a
    /// draw allowed is counted as made.
    fn ready(&mut self, now: Instant, last_one: bool) -> bool {
        let due = last_one || self.last.is_none_or(|t| now.saturating_duration_since(t) >= self.every);
        if due {
            self.last = Some(now);
        }
        due
    }
}

/// Prints a job's progress and warnings on stderr.
pub struct Progress {
    style: ProgressStyle,
    start: Instant,
    /// When the last plain line mid-frame was printed.
    last_line: Mutex<Instant>,
    /// When the bar may be redrawn.
    redraw: Mutex<Throttle>,
}

impl Progress {
    /// Progress in `style` (`Auto` decided now, from whether stderr is a terminal).
    pub fn new(style: ProgressStyle) -> Progress {
        let style = match style {
            ProgressStyle::Auto if std::io::stderr().is_terminal() => ProgressStyle::Bar,
            ProgressStyle::Auto => ProgressStyle::Plain,
            s => s,
        };
        Progress {
            style,
            start: Instant::now(),
            last_line: Mutex::new(Instant::now()),
            redraw: Mutex::new(Throttle::new(BAR_EVERY)),
        }
    }

    fn figures(&self, at: RenderProgress<'_>, frac: f64) -> (f64, f64, f64) {
        let progress = (at.done as f64 + frac) / at.total.max(1) as f64;
        let elapsed = self.start.elapsed().as_secs_f64();
        let eta = if progress > 0.0 { elapsed / progress - elapsed } else { 0.0 };
        (progress, elapsed, eta)
    }

    /// Redraws the bar, unless it was redrawn less than [`BAR_EVERY`] ago
    /// and this is not the job's last update.
    fn bar(&self, at: RenderProgress<'_>, frac: f64, last_one: bool) {
        let Ok(mut redraw) = self.redraw.lock() else { return };
        if !redraw.ready(Instant::now(), last_one) {
            return;
        }
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
            self.bar(at, 0.0, false);
        }
    }
    fn pixels(&self, at: RenderProgress<'_>, frac: f64) {
        match self.style {
            ProgressStyle::Bar => self.bar(at, frac, false),
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
        if self.style == ProgressStyle::Bar && at.done + 1 >= at.total {
            // The job's last layer-frame: the bar ends at 100 %, whenever it was last drawn.
            self.bar(RenderProgress { done: at.total.saturating_sub(1), ..at }, 1.0, true);
        }
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_bar_redraws_at_most_ten_times_a_second_and_always_at_the_end() {
        let t0 = Instant::now();
        let mut t = Throttle::new(BAR_EVERY);
        // 483 updates in 3.5 s (what a small render sent): 35 or 36 redraws, not 483.
        let drawn = (0..483).filter(|&i| t.ready(t0 + Duration::from_micros(i * 3_500_000 / 483), false)).count();
        assert!((35..=36).contains(&drawn), "{drawn} redraws");
        // The first update draws; one 10 ms later does not; one 100 ms later does.
        let mut t = Throttle::new(BAR_EVERY);
        assert!(t.ready(t0, false));
        assert!(!t.ready(t0 + Duration::from_millis(10), false));
        assert!(t.ready(t0 + Duration::from_millis(110), false));
        // The last update draws however soon it comes.
        assert!(t.ready(t0 + Duration::from_millis(111), true));
        // A clock that goes backwards (updates from several threads) never draws early.
        assert!(!t.ready(t0, false));
    }
}
