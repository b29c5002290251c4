//! Two jobs on two cores: what an engine asks of the shell to split its work (the engine holds
//! no threads; `audio::helper` and `audio::host_pool` implement it).

/// Runs two jobs at once, one on another core. The real-time shell implements it with a helper
/// thread or a host's thread pool (the engine holds no threads); the exact pool uses it to split a
/// block's passes and its steps over two cores.
pub trait Pair {
    /// Run `there` on the other core and `here` on this one (a host's pool may run `here` on one
    /// of its workers too, hence `Send`), the two started together (they may
    /// wait for each other: `there` must run to its end, or panic, whenever `join` returns
    /// `true`), and return `true` when both have finished. When the other core
    /// cannot start `there` promptly, run neither and return `false`: the caller then does the
    /// work alone, so a late core costs one core's time, not a wait of unknown length.
    fn join(&self, there: &mut (dyn FnMut() + Send), here: &mut (dyn FnMut() + Send)) -> bool;

    /// Whether every `join` would now return `false` at once (a host's thread pool that runs its
    /// tasks one after another): the caller may ask another pair instead.
    fn declines(&self) -> bool {
        false
    }
}
