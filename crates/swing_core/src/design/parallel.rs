//! Independent checks side by side: one candidate's closed loops on several plants and lags,
//! its twin flights with and without noise. Every job is deterministic and the results come
//! back in the jobs' order, so the outcome is the same on one core or many.

/// Threads to use for `jobs` independent jobs: one per job, at most the machine's cores.
pub fn threads_for(jobs: usize) -> usize {
    std::thread::available_parallelism()
        .map_or(1, |n| n.get())
        .min(jobs)
}

/// `f` applied to every item, on up to as many threads as the machine has cores; the
/// results in the items' order. A job that panics panics the caller, as in a loop.
pub fn map<I: Send, T: Send>(items: Vec<I>, f: impl Fn(I) -> T + Sync) -> Vec<T> {
    let threads = threads_for(items.len());
    if threads <= 1 {
        return items.into_iter().map(f).collect();
    }
    let count = items.len();
    let mut shares: Vec<Vec<(usize, I)>> = (0..threads).map(|_| Vec::new()).collect();
    for (k, item) in items.into_iter().enumerate() {
        shares[k % threads].push((k, item));
    }
    let f = &f;
    let mut out: Vec<Option<T>> = (0..count).map(|_| None).collect();
    std::thread::scope(|s| {
        let handles: Vec<_> = shares
            .into_iter()
            .map(|share| {
                s.spawn(move || {
                    share
                        .into_iter()
                        .map(|(k, item)| (k, f(item)))
                        .collect::<Vec<_>>()
                })
            })
            .collect();
        for h in handles {
            match h.join() {
                Ok(done) => {
                    for (k, t) in done {
                        out[k] = Some(t);
                    }
                }
                Err(panic) => std::panic::resume_unwind(panic),
            }
        }
    });
    out.into_iter().flatten().collect()
}

/// `a()` on this thread and `b()` on another when the machine has a second core (else one
/// after the other); both results.
pub fn join<A, B: Send>(a: impl FnOnce() -> A, b: impl FnOnce() -> B + Send) -> (A, B) {
    if threads_for(2) < 2 {
        return (a(), b());
    }
    std::thread::scope(|s| {
        let other = s.spawn(b);
        let first = a();
        match other.join() {
            Ok(second) => (first, second),
            Err(panic) => std::panic::resume_unwind(panic),
        }
    })
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
}
