//! Independent work on every core of the machine: each key's preparation (`play`), each key's
//! eigen-analysis (`unacorda analyze`).

/// `f` of every item, on as many threads as the machine has cores (at most one per item), the
/// results in the items' order; the first error (in that order) if any. Thread `t` takes items
/// `t`, `t + threads`, …, so that the keyboard's heavy bass keys and light treble keys spread
/// evenly.
pub fn map_on_cores<T: Sync, R: Send, E: Send>(
    items: &[T],
    f: impl Fn(&T) -> Result<R, E> + Sync,
) -> Result<Vec<R>, E> {
    let threads = std::thread::available_parallelism()
        .map_or(1, |n| n.get())
        .min(items.len())
        .max(1);
    let f = &f;
    // Each thread stops at its first error and says where it was: of those, the first in the
    // items' order is the error.
    let parts = std::thread::scope(|scope| {
        let handles: Vec<_> = (0..threads)
            .map(|t| {
                scope.spawn(move || {
                    (t..items.len())
                        .step_by(threads)
                        .map(|i| f(&items[i]).map_err(|e| (i, e)))
                        .collect::<Result<Vec<R>, (usize, E)>>()
                })
            })
            .collect();
        handles
            .into_iter()
            .map(|h| h.join().expect("a worker thread panicked"))
            .collect::<Vec<_>>()
    });
    let mut done = Vec::with_capacity(threads);
    let mut first: Option<(usize, E)> = None;
    for part in parts {
        match part {
            Ok(results) => done.push(results.into_iter()),
            Err((i, e)) => {
                if first.as_ref().is_none_or(|(j, _)| i < *j) {
                    first = Some((i, e));
                }
            }
        }
    }
    if let Some((_, e)) = first {
        return Err(e);
    }
    Ok((0..items.len())
        .map(|i| done[i % threads].next().expect("one result per item"))
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn results_come_back_in_the_items_order() {
        let items: Vec<u32> = (0..37).collect();
        let squares: Result<Vec<u32>, ()> = map_on_cores(&items, |x| Ok(x * x));
        assert_eq!(
            squares.unwrap(),
            items.iter().map(|x| x * x).collect::<Vec<_>>()
        );
        let failed = map_on_cores(&items, |&x| if x % 10 == 7 { Err(x) } else { Ok(x) });
        assert_eq!(failed, Err(7), "the first error in the items' order");
        // Errors on every thread (items 5, 6, 7, …, taken by different threads): still the first.
        let failed = map_on_cores(&items, |&x| if x >= 5 { Err(x) } else { Ok(x) });
        assert_eq!(
            failed,
            Err(5),
            "the first error in the items' order, of any thread"
        );
        let none: Result<Vec<u32>, ()> = map_on_cores(&[] as &[u32], |x| Ok(*x));
        assert_eq!(none.unwrap(), Vec::<u32>::new());
    }
}
