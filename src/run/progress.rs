//! Progress of long phases, on rank 0: a bar on a terminal (indicatif),
//! plain periodic lines otherwise.
//!
//! A phase that runs longer than [`DEFAULT_AFTER`] (or the seconds in the
//! environment variable `OCTMESH_PROGRESS_AFTER`) shows its name and, where
//! it counts its work, the octants done of the expected count with the rate
//! and the time left. Counting is one relaxed atomic store per batch of
//! leaves ([`set_done`]); the drawing runs on its own thread, which touches
//! neither MPI nor the octree. The count is rank 0's own, scaled by the
//! number of ranks: the partition gives every rank about the same share.

use std::io::{IsTerminal, Write};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

/// How long a phase runs before its progress shows.
pub const DEFAULT_AFTER: Duration = Duration::from_secs(1);

/// Seconds between two plain progress lines.
const LINE_EVERY: Duration = Duration::from_secs(5);

/// Work done by this process in the current phase (octants).
static DONE: AtomicU64 = AtomicU64::new(0);

/// Records that this process has done `n` units (octants) of the current
/// phase's work. Cheap: call it every few thousand leaves.
#[inline]
pub fn set_done(n: u64) {
    DONE.store(n, Ordering::Relaxed);
}

/// Where progress goes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Style {
    /// An indicatif bar on the terminal (stderr).
    Bar,
    /// A plain line on stderr every few seconds.
    Lines,
}

impl Style {
    /// A bar when stderr is a terminal, else lines.
    pub fn detect() -> Style {
        if std::io::stderr().is_terminal() {
            Style::Bar
        } else {
            Style::Lines
        }
    }
}

/// The delay before progress shows: `OCTMESH_PROGRESS_AFTER` seconds, or
/// [`DEFAULT_AFTER`].
pub fn delay() -> Duration {
    std::env::var("OCTMESH_PROGRESS_AFTER")
        .ok()
        .and_then(|s| s.parse::<f64>().ok())
        .filter(|s| s.is_finite() && *s >= 0.0)
        .map_or(DEFAULT_AFTER, Duration::from_secs_f64)
}

/// The display of one phase; it stops and clears when dropped.
pub struct Progress {
    stop: Arc<AtomicBool>,
    thread: Option<JoinHandle<()>>,
}

impl Progress {
    /// Starts showing phase `name` after `after`: `expected` octants over
    /// all ranks when the phase counts them, `ranks` to scale this rank's
    /// count.
    pub fn start(
        name: &str,
        expected: Option<u64>,
        ranks: u64,
        style: Style,
        after: Duration,
    ) -> Progress {
        set_done(0);
        let stop = Arc::new(AtomicBool::new(false));
        let flag = stop.clone();
        let name = name.to_string();
        let thread = std::thread::Builder::new()
            .name("octmesh-progress".into())
            .spawn(move || show(&name, expected, ranks.max(1), style, after, &flag))
            .ok();
        Progress { stop, thread }
    }
}

impl Drop for Progress {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

/// The drawing loop of one phase.
fn show(
    name: &str,
    expected: Option<u64>,
    ranks: u64,
    style: Style,
    after: Duration,
    stop: &AtomicBool,
) {
    let start = Instant::now();
    let tick = Duration::from_millis(50);
    while start.elapsed() < after {
        if stop.load(Ordering::Relaxed) {
            return;
        }
        std::thread::sleep(tick);
    }
    let done = || DONE.load(Ordering::Relaxed).saturating_mul(ranks);
    match style {
        Style::Bar => {
            let bar = match expected {
                Some(n) => indicatif::ProgressBar::new(n.max(1)).with_style(
                    indicatif::ProgressStyle::with_template(
                        "  {prefix:<12} [{bar:30}] {human_pos}/{human_len} octants, {per_sec}, {eta} left",
                    )
                    .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar())
                    .progress_chars("=> "),
                ),
                None => indicatif::ProgressBar::new_spinner().with_style(
                    indicatif::ProgressStyle::with_template("  {prefix:<12} {spinner} {elapsed}")
                        .unwrap_or_else(|_| indicatif::ProgressStyle::default_spinner()),
                ),
            };
            bar.set_draw_target(indicatif::ProgressDrawTarget::stderr());
            bar.set_prefix(name.to_string());
            while !stop.load(Ordering::Relaxed) {
                match expected {
                    Some(n) => bar.set_position(done().min(n)),
                    None => bar.tick(),
                }
                std::thread::sleep(tick);
            }
            bar.finish_and_clear();
        }
        Style::Lines => {
            let mut next = Duration::ZERO;
            while !stop.load(Ordering::Relaxed) {
                let t = start.elapsed();
                if t >= next {
                    let _ = writeln!(std::io::stderr(), "{}", line(name, done(), expected, t));
                    next = t + LINE_EVERY;
                }
                std::thread::sleep(tick);
            }
        }
    }
}

/// One plain progress line.
fn line(name: &str, done: u64, expected: Option<u64>, t: Duration) -> String {
    let secs = t.as_secs_f64();
    match expected {
        Some(n) if done > 0 => {
            let rate = done as f64 / secs.max(1e-9);
            let left = n.saturating_sub(done) as f64 / rate;
            format!(
                "  progress: {name}: {done} of about {n} octants ({:.0}%), {rate:.3e} octants/s, \
                 about {left:.0} s left",
                100.0 * done as f64 / n.max(1) as f64
            )
        }
        _ => format!("  progress: {name}: running for {secs:.0} s"),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lines_give_count_rate_and_time_left() {
        let l = line("refine", 500, Some(1000), Duration::from_secs(2));
        assert!(l.contains("refine: 500 of about 1000 octants (50%)"), "{l}");
        assert!(l.contains("about 2 s left"), "{l}");
        let l = line("nodes", 0, None, Duration::from_secs(3));
        assert!(l.contains("nodes: running for 3 s"), "{l}");
    }

    #[test]
    fn a_short_phase_shows_nothing_and_stops_at_once() {
        let t = Instant::now();
        drop(Progress::start(
            "x",
            Some(10),
            1,
            Style::Lines,
            Duration::from_secs(60),
        ));
        assert!(t.elapsed() < Duration::from_secs(5));
    }
}
