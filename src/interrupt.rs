//! SIGINT and SIGTERM as a request to stop: once [`install`]ed, the first
//! signal only sets a flag that the run's observer reads after each step
//! ([`requested`], through `Observer::interruption` of
//! [`mpm_physics::simulation`]); the run then finishes that
//! step's outputs, writes `run.json` with status `interrupted` and the CLI
//! exits with 128 + the signal number (130 for SIGINT, 143 for SIGTERM). A
//! campaign's runs (threads of the process) each stop so and the campaign
//! starts no other; a study passes the signal on to its run process. A
//! second signal while the first is pending ends the process at once with the
//! same code (the outputs already written stay whole: see
//! [`crate::atomic_file`]).

use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::{Arc, OnceLock};

pub use mpm_physics::simulation::Interruption;

struct Flags {
    /// Set by the first signal (makes a second one end the process).
    pending: Arc<AtomicBool>,
    /// The first signal's number.
    signal: Arc<AtomicUsize>,
}

fn flags() -> &'static Flags {
    static FLAGS: OnceLock<Flags> = OnceLock::new();
    FLAGS.get_or_init(|| Flags {
        pending: Arc::new(AtomicBool::new(false)),
        signal: Arc::new(AtomicUsize::new(0)),
    })
}

/// Catch SIGINT and SIGTERM for the rest of the process (the `run`,
/// `resume`, `campaign` and `study` commands: every run in progress stops
/// after its step, a campaign or study starts no further run). Without it a
/// signal ends the process as usual and [`requested`] stays `None` (library
/// use).
pub fn install() -> std::io::Result<()> {
    use signal_hook::consts::{SIGINT, SIGTERM};
    let f = flags();
    for signal in [SIGINT, SIGTERM] {
        let code = Interruption { signal }.exit_code().into();
        // registered first: on a second signal the flag is already set
        signal_hook::flag::register_conditional_shutdown(signal, code, Arc::clone(&f.pending))?;
        // the number before the flag: a reader that sees the flag sees it
        let number = usize::try_from(signal).unwrap_or(0);
        signal_hook::flag::register_usize(signal, Arc::clone(&f.signal), number)?;
        signal_hook::flag::register(signal, Arc::clone(&f.pending))?;
    }
    Ok(())
}

/// The signal that asked the run to stop, if one came.
pub fn requested() -> Option<Interruption> {
    let f = flags();
    if !f.pending.load(Ordering::SeqCst) {
        return None;
    }
    let signal = i32::try_from(f.signal.load(Ordering::SeqCst)).unwrap_or(0);
    Some(Interruption { signal })
}
