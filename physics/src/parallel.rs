//! Where the parallel loops run: the thread that calls them is one of the
//! rayon workers.
//!
//! A parallel loop called from a thread outside the pool is handed to a
//! worker while the caller waits (a futex wake-up and a sleep per loop). An
//! implicit step has dozens of short loops, so with one thread that hand-over
//! cost more than the loops' work: measured on the local vertical cut at
//! h = 0.1 m, 300 steps, `RAYON_NUM_THREADS=1`, the P2G stage took 3.1–3.4 s
//! handed over and 0.36 s on the calling thread (wall 20.7–21.6 s → 13.8 s,
//! the same bytes out). The results never depend on the threads: every sum
//! has a fixed order (crate::transfer).

/// Makes the calling thread worker 0 of the global pool (of
/// `RAYON_NUM_THREADS` workers, or one per core): with one thread every loop
/// runs on it. Call it first thing on the main thread; `false` if the global
/// pool was already built (it then stays as it is).
pub fn join_global_pool() -> bool {
    rayon::ThreadPoolBuilder::new()
        .use_current_thread()
        .build_global()
        .is_ok()
}

/// A pool of `threads` workers whose worker 0 is the calling thread, for a
/// campaign job: install the job's run in it. Each job then has workers of
/// its own (two jobs do not queue for the workers of one shared pool: with
/// `RAYON_NUM_THREADS=1` and `--jobs 2` both jobs' loops once ran on one
/// worker). A thread can be worker 0 of one such pool only. `None` if the
/// pool cannot be built (the job then uses the global pool).
pub fn job_pool(threads: usize) -> Option<rayon::ThreadPool> {
    rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .use_current_thread()
        .build()
        .ok()
}

#[cfg(test)]
mod tests {
    use super::*;
    use rayon::prelude::*;
    use std::collections::BTreeSet;

    /// A job pool has the calling thread as its worker 0: with one thread a
    /// parallel loop runs wholly on it (no hand-over), with two it takes
    /// part. Each case on a thread of its own, as each campaign job.
    #[test]
    fn job_pool_runs_loops_on_the_calling_thread() {
        for threads in [1, 2] {
            std::thread::spawn(move || {
                let caller = format!("{:?}", std::thread::current().id());
                let pool = job_pool(threads).expect("a pool");
                let ran_on: BTreeSet<String> = pool.install(|| {
                    assert_eq!(rayon::current_thread_index(), Some(0));
                    assert_eq!(rayon::current_num_threads(), threads);
                    (0..10_000)
                        .into_par_iter()
                        .with_max_len(16)
                        .map(|_| format!("{:?}", std::thread::current().id()))
                        .collect()
                });
                assert!(ran_on.contains(&caller), "{threads} threads");
                if threads == 1 {
                    assert_eq!(ran_on.len(), 1);
                }
                // a second pool with this thread as worker 0 is refused
                assert!(job_pool(1).is_none());
            })
            .join()
            .expect("the job thread");
        }
    }
}
