//! Ordered parallel processing: items are worked on by the current rayon pool, at most a
//! window of them at a time, and handed to a sink in their order while the next ones are
//! being worked on. The sink (writing a frame, say) thus overlaps the work, no thread waits
//! at a chunk boundary, and memory stays bounded by the window.

use std::collections::BTreeMap;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::mpsc;
use std::time::Duration;

/// Runs `work(0) .. work(n - 1)` on the current rayon pool with at most `window` items in
/// flight (worked on, or done and waiting for their turn), and calls `sink` with the results
/// in index order, on the calling thread, as soon as each one's predecessors are sunk.
///
/// Stops at the first error in index order (of `work` or of `sink`) and returns it: items
/// after it are not sunk, and the items already started finish before this returns.
///
/// The calling thread may itself be a thread of the pool (inside `ThreadPool::install`, even
/// of one thread): while it waits for an item it runs the pool's pending work.
pub(crate) fn for_each_ordered<T, E, W, S>(
    n: usize,
    window: usize,
    work: W,
    mut sink: S,
) -> Result<(), E>
where
    T: Send,
    E: Send,
    W: Fn(usize) -> Result<T, E> + Sync,
    S: FnMut(T) -> Result<(), E>,
{
    let window = window.max(1);
    // the smallest index that failed (usize::MAX: none); items after it are never sunk
    let failed = AtomicUsize::new(usize::MAX);
    let (tx, rx) = mpsc::channel::<(usize, Result<T, E>)>();
    let in_pool = rayon::current_thread_index().is_some();
    let (work, failed_ref) = (&work, &failed);
    rayon::in_place_scope(|scope| {
        let spawn = |i: usize| {
            let tx = tx.clone();
            scope.spawn(move |_| {
                // items queued after one that failed are dropped unworked: they are never
                // sunk (those before it still are, so they still run)
                if i > failed_ref.load(Ordering::Relaxed) {
                    return;
                }
                let r = work(i);
                if r.is_err() {
                    failed_ref.fetch_min(i, Ordering::Relaxed);
                }
                // the receiver lives until every spawned job has finished
                let _ = tx.send((i, r));
            });
        };
        let mut spawned = 0;
        while spawned < n.min(window) {
            spawn(spawned);
            spawned += 1;
        }
        let mut ready: BTreeMap<usize, Result<T, E>> = BTreeMap::new();
        for want in 0..n {
            let r = loop {
                if let Some(r) = ready.remove(&want) {
                    break r;
                }
                let got = if in_pool {
                    // never block a pool thread: it may be the one that has to run the job
                    match rx.try_recv() {
                        Ok(item) => Some(item),
                        Err(_) => match rayon::yield_now() {
                            Some(rayon::Yield::Executed) => None,
                            _ => rx.recv_timeout(Duration::from_micros(200)).ok(),
                        },
                    }
                } else {
                    rx.recv().ok()
                };
                if let Some((i, r)) = got {
                    ready.insert(i, r);
                }
            };
            let sunk = r.and_then(&mut sink);
            if let Err(e) = sunk {
                failed.fetch_min(want, Ordering::Relaxed);
                return Err(e);
            }
            if spawned < n {
                spawn(spawned);
                spawned += 1;
            }
        }
        Ok(())
    })
}

#[cfg(test)]
mod tests {
    use super::for_each_ordered;

    fn run(
        threads: usize,
        n: usize,
        window: usize,
        fail_at: Option<usize>,
    ) -> (Vec<usize>, Result<(), String>) {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .expect("a thread pool");
        let mut seen = Vec::new();
        let r = pool.install(|| {
            for_each_ordered(
                n,
                window,
                |i| {
                    // uneven work, so that items finish out of order
                    std::thread::sleep(std::time::Duration::from_micros(
                        ((i * 7919) % 13) as u64 * 50,
                    ));
                    if Some(i) == fail_at {
                        Err(format!("item {i} failed"))
                    } else {
                        Ok(i * 10)
                    }
                },
                |v| {
                    seen.push(v / 10);
                    Ok(())
                },
            )
        });
        (seen, r)
    }

    #[test]
    fn results_reach_the_sink_in_order_with_any_pool_and_window() {
        for threads in [1, 2, 3] {
            for window in [1, 2, 5, 64] {
                let (seen, r) = run(threads, 40, window, None);
                assert_eq!(r, Ok(()));
                assert_eq!(
                    seen,
                    (0..40).collect::<Vec<_>>(),
                    "{threads} threads, window {window}"
                );
            }
        }
    }

    #[test]
    fn the_first_error_in_order_stops_the_sink() {
        for threads in [1, 2] {
            let (seen, r) = run(threads, 40, 6, Some(17));
            assert_eq!(r, Err("item 17 failed".to_string()));
            assert_eq!(seen, (0..17).collect::<Vec<_>>());
        }
    }

    #[test]
    fn a_sink_error_stops_at_once_and_from_outside_a_pool() {
        let mut sunk = 0;
        let r = for_each_ordered(30, 4, Ok::<usize, String>, |i| {
            sunk += 1;
            if i == 9 {
                Err("disk full".to_string())
            } else {
                Ok(())
            }
        });
        assert_eq!(r, Err("disk full".to_string()));
        assert_eq!(sunk, 10);
        assert_eq!(
            for_each_ordered(0, 4, Ok::<usize, String>, |_| Ok(())),
            Ok(())
        );
    }
}
