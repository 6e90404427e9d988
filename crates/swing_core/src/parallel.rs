//! Independent jobs side by side on rayon's pool: the search's delays, one candidate's
//! closed loops on several plants and lags, its twin flights with and without noise. Every
//! job is deterministic and the results come back in the jobs' order, so the outcome is the
//! same on one core or many. At the bottom of the crate: it knows nothing of the jobs.

/// Jobs to start side by side for `jobs` independent jobs: one per job, at most the pool's
/// threads (one per core; `RAYON_NUM_THREADS` sets it).
pub fn threads_for(jobs: usize) -> usize {
    rayon::current_num_threads().min(jobs).max(1)
}

/// `f` applied to every item on rayon's pool; the results in the items' order. Nested maps
/// share the same threads: a core whose job ends first takes up the jobs of another's
/// nested map (work stealing), so unequal jobs keep every core busy without more threads
/// than cores. A job that panics panics the caller, as in a loop.
pub fn map<I: Send, T: Send>(items: Vec<I>, f: impl Fn(I) -> T + Sync + Send) -> Vec<T> {
    use rayon::prelude::*;
    items.into_par_iter().map(f).collect()
}

/// `a()` and `b()` side by side on rayon's pool (one after the other on one core); both
/// results.
pub fn join<A: Send, B: Send>(
    a: impl FnOnce() -> A + Send,
    b: impl FnOnce() -> B + Send,
) -> (A, B) {
    rayon::join(a, b)
}

/// The loop `for item in items { let t = f(item); if done(&t) { break } }`: the results up
/// to and including the first that is done, in order. Items past the first may start ahead
/// on a core that would otherwise idle (each later item is offered to the pool while the
/// ones before it run); an item nobody took ahead runs only if none before it was done. So
/// the results are the loop's. The time is the loop's or less, except that an item already
/// taken ahead is waited for even when one before it turns out done.
pub fn until<I: Sync, T: Send>(
    items: &[I],
    f: impl Fn(&I) -> T + Sync,
    done: impl Fn(&T) -> bool + Sync,
) -> Vec<T> {
    use std::sync::atomic::{AtomicUsize, Ordering};
    // The index of the first item found done, so far.
    let first_done = AtomicUsize::new(usize::MAX);
    fn from<I: Sync, T: Send>(
        k: usize,
        items: &[I],
        f: &(impl Fn(&I) -> T + Sync),
        done: &(impl Fn(&T) -> bool + Sync),
        first_done: &AtomicUsize,
    ) -> Vec<Option<T>> {
        if k >= items.len() {
            return Vec::new();
        }
        let (head, tail) = join(
            || {
                if first_done.load(Ordering::Acquire) < k {
                    return None;
                }
                let t = f(&items[k]);
                if done(&t) {
                    first_done.fetch_min(k, Ordering::AcqRel);
                }
                Some(t)
            },
            || from(k + 1, items, f, done, first_done),
        );
        std::iter::once(head).chain(tail).collect()
    }
    let mut out = Vec::new();
    // A skipped item (None) follows one that is done, where the loop has stopped.
    for t in from(0, items, &f, &done, &first_done)
        .into_iter()
        .map_while(|t| t)
    {
        let stop = done(&t);
        out.push(t);
        if stop {
            break;
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn results_come_back_in_the_items_order() {
        let squares = map((0..37).collect(), |k: u64| k * k);
        assert_eq!(squares, (0..37).map(|k| k * k).collect::<Vec<_>>());
        assert!(map(Vec::<u64>::new(), |k| k).is_empty());
        assert_eq!(join(|| 1, || "two"), (1, "two"));
    }

    #[test]
    fn until_returns_the_loops_results_whatever_ran_ahead() {
        // Later items are quicker, so any taken ahead finish first; the first done is 5.
        let items: Vec<u64> = (0..12).collect();
        let slow = |k: &u64| {
            std::thread::sleep(std::time::Duration::from_millis(12 - *k));
            *k * 10
        };
        for _ in 0..5 {
            let got = until(&items, slow, |t| *t == 50 || *t == 90);
            assert_eq!(got, vec![0, 10, 20, 30, 40, 50]);
        }
        assert_eq!(until(&items, |k| *k, |_| false), items);
        assert_eq!(until(&items, |k| *k, |_| true), vec![0]);
        assert!(until(&Vec::<u64>::new(), |k| *k, |_| true).is_empty());
    }
}
