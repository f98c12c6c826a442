//! Lower CPU priority for work that must not take the presenter's time:
//! the frame writer's disk and compression threads, and the in-process
//! server, which stands in for a remote machine.
//!
//! On Linux a thread's nice value is its own, and the threads it starts
//! inherit it; elsewhere nothing changes.

/// The nice value of background work (Linux; 0 is the default, 19 the
/// lowest priority): a tenth of a default thread's CPU share under
/// contention, all of it when the cores are idle.
pub const BACKGROUND_NICE: i32 = 10;

/// How far the in-process server's work steps back from the presenter's
/// and the generator's (`client run --server-priority`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, clap::ValueEnum)]
pub enum Background {
    /// Nice [`BACKGROUND_NICE`]: a tenth of a default thread's CPU share
    /// under contention. It still takes a share of every core the
    /// generator wants: on two cores at 640×360 the server's rasteriser
    /// and encoder took about half of the samples of a live run.
    #[default]
    Low,
    /// Linux's `SCHED_IDLE`: only time no other thread wants, all of it
    /// when the cores are idle. The generator keeps its cores (gffe at
    /// 640×360 on two cores missed about half as many vsyncs), but a
    /// machine busy with anything else starves the server (3 frames in
    /// 10 s beside three busy loops, against 56 at [`Background::Low`]).
    /// Elsewhere, and where Linux refuses it, [`Background::Low`].
    Idle,
}

/// Lowers the calling thread's priority to [`BACKGROUND_NICE`] (never
/// raises it); threads it starts from now on inherit it. Best effort: a
/// refusal only costs the presenter time, and is logged (`what` names the
/// work).
pub fn lower_this_thread(what: &str) {
    lower_this_thread_to(what, Background::Low);
}

/// Lowers the calling thread's priority to `to` (never raises it), as
/// [`lower_this_thread`] does.
pub fn lower_this_thread_to(what: &str, to: Background) {
    #[cfg(target_os = "linux")]
    {
        if to == Background::Idle {
            // SAFETY: `sched_setscheduler` with pid 0 changes only the
            // calling thread's policy (Linux's per-thread semantics), from
            // a parameter it reads and does not keep, and reports failure
            // by its return value.
            let param = libc::sched_param { sched_priority: 0 };
            if unsafe { libc::sched_setscheduler(0, libc::SCHED_IDLE, &param) } == 0 {
                return;
            }
            tracing::debug!(
                "{what} is not idle-scheduled: {}",
                std::io::Error::last_os_error()
            );
        }
        // SAFETY: `gettid` has no preconditions; `setpriority` with
        // `PRIO_PROCESS` and a thread id changes only that thread's nice
        // value (Linux's per-thread semantics) and reports failure by its
        // return value.
        // A thread already below that priority stays where it is.
        let failed = unsafe {
            let tid = libc::gettid() as libc::id_t;
            libc::getpriority(libc::PRIO_PROCESS, tid) < BACKGROUND_NICE
                && libc::setpriority(libc::PRIO_PROCESS, tid, BACKGROUND_NICE) != 0
        };
        if failed {
            tracing::debug!(
                "{what} keeps its priority: {}",
                std::io::Error::last_os_error()
            );
        }
    }
    #[cfg(not(target_os = "linux"))]
    let _ = (what, to);
}

/// Runs `start` on a thread of its own at [`BACKGROUND_NICE`] and returns
/// its result (an error only where no thread can be started): whatever threads `start` starts (a renderer's driver
/// threads, an encoder's, a producer loop) keep the lower priority for
/// their lifetime.
///
/// The CPU generator's thread pool (rayon's global pool) is started first,
/// here, at the caller's priority: started lazily by background work, its
/// threads would inherit the lower priority and generate at it.
pub fn start_in_background<T: Send>(
    what: &str,
    start: impl FnOnce() -> T + Send,
) -> std::io::Result<T> {
    start_at(what, Background::Low, start)
}

/// [`start_in_background`] at priority `to`.
pub fn start_at<T: Send>(
    what: &str,
    to: Background,
    start: impl FnOnce() -> T + Send,
) -> std::io::Result<T> {
    rayon::current_num_threads();
    std::thread::scope(|s| {
        let thread = std::thread::Builder::new()
            .name(format!("{what} (start)"))
            .spawn_scoped(s, || {
                lower_this_thread_to(what, to);
                start()
            })?;
        match thread.join() {
            Ok(v) => Ok(v),
            Err(panic) => std::panic::resume_unwind(panic),
        }
    })
}

/// A [`host::source::Opener`]: opens an interactive session's source (its
/// renderer, encoder and producer) with [`start_in_background`]; where no
/// thread can be started, here, at this thread's priority.
pub fn open_in_background(open: &mut (dyn FnMut() + Send)) {
    open_at(open, Background::Low);
}

/// [`open_in_background`] at [`Background::Idle`].
pub fn open_idle(open: &mut (dyn FnMut() + Send)) {
    open_at(open, Background::Idle);
}

fn open_at(open: &mut (dyn FnMut() + Send), to: Background) {
    const WHAT: &str = "an interactive session's source";
    if let Err(e) = start_at(WHAT, to, &mut *open) {
        tracing::warn!("{WHAT} opens at normal priority: {e}");
        open();
    }
}

#[cfg(all(test, target_os = "linux"))]
mod tests {
    use super::*;

    fn nice_of_this_thread() -> i32 {
        // SAFETY: as above; `getpriority` returns the nice value (which
        // may be -1, so errno would tell an error apart; none occurs for
        // the calling thread).
        unsafe { libc::getpriority(libc::PRIO_PROCESS, libc::gettid() as libc::id_t) }
    }

    /// Work started in the background, and the threads it starts, run at
    /// the lower priority; the caller and rayon's pool keep theirs.
    #[test]
    fn background_work_and_its_threads_run_at_the_lower_priority() {
        let caller = nice_of_this_thread();
        let (own, child, pool) = start_in_background("test work", || {
            let child = std::thread::spawn(nice_of_this_thread).join().unwrap();
            // Work in the pool from the background (which would start it
            // there, were it not started yet).
            let pool = rayon::broadcast(|_| nice_of_this_thread());
            (nice_of_this_thread(), child, pool)
        })
        .unwrap();
        // Nice values only go up without privileges, and may already be
        // above the background value.
        let expected = caller.max(BACKGROUND_NICE);
        assert_eq!((own, child), (expected, expected));
        assert_eq!(nice_of_this_thread(), caller);
        assert!(pool.iter().all(|&n| n == caller), "{pool:?} vs {caller}");
    }

    /// An interactive session's source is opened once, on a thread at the
    /// lower priority, and the opener returns when it is done.
    #[test]
    fn a_session_source_opens_in_the_background() {
        let caller = nice_of_this_thread();
        let mut opened = Vec::new();
        open_in_background(&mut || {
            let child = std::thread::spawn(nice_of_this_thread).join().unwrap();
            opened.push((nice_of_this_thread(), child));
        });
        let expected = caller.max(BACKGROUND_NICE);
        assert_eq!(opened, [(expected, expected)]);
        assert_eq!(nice_of_this_thread(), caller);
    }

    fn policy_of_this_thread() -> i32 {
        // SAFETY: `sched_getscheduler(0)` reads the calling thread's
        // policy and has no preconditions.
        unsafe { libc::sched_getscheduler(0) }
    }

    /// Work started idle, and the threads it starts, are scheduled
    /// `SCHED_IDLE`; the caller and rayon's pool keep their policy, and an
    /// interactive session's source opens idle with [`open_idle`].
    #[test]
    fn idle_work_and_its_threads_are_idle_scheduled() {
        let caller = policy_of_this_thread();
        assert_ne!(caller, libc::SCHED_IDLE);
        let (own, child, pool) = start_at("test work", Background::Idle, || {
            let child = std::thread::spawn(policy_of_this_thread).join().unwrap();
            let pool = rayon::broadcast(|_| policy_of_this_thread());
            (policy_of_this_thread(), child, pool)
        })
        .unwrap();
        assert_eq!((own, child), (libc::SCHED_IDLE, libc::SCHED_IDLE));
        assert_eq!(policy_of_this_thread(), caller);
        assert!(pool.iter().all(|&p| p == caller), "{pool:?} vs {caller}");
        let mut opened = Vec::new();
        open_idle(&mut || opened.push(policy_of_this_thread()));
        assert_eq!(opened, [libc::SCHED_IDLE]);
        assert_eq!(policy_of_this_thread(), caller);
    }
}
