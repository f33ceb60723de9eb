//! The threads that run the racers a race of planners hands over (see
//! [`super::MotionSettings::racers`]), kept for the process.
//!
//! A thread with nothing to do looks for work a while before it sleeps, so a racer handed over
//! meanwhile starts with no system call on the caller's side. Waking a sleeping thread (rayon's
//! pool, a condition variable) cost the handing racer 35 µs on average on the 2-core machine of
//! the MotionBenchMaker runs, up to 220 µs, out of its own planning time.
//!
//! How long it looks is the process's to choose ([`set_racer_look`], 50 ms by default): a
//! longer look finds more hand-overs with the thread awake, a shorter one leaves the core
//! sooner to the rest of the process.

use std::collections::VecDeque;
use std::sync::atomic::{AtomicBool, AtomicU64, AtomicUsize, Ordering};
use std::sync::{Condvar, Mutex, MutexGuard, OnceLock, PoisonError};
use std::time::{Duration, Instant};

/// How long a racer thread with nothing to do looks for work before it sleeps, unless
/// [`set_racer_look`] says otherwise. `bench mbm --threads 2` builds each problem's model
/// between races: with 2 ms most hand-overs found the thread asleep (38 µs on average over the
/// three generated families bookshelf_tall, bookshelf_thin and table_under_pick); with 50 ms,
/// 2.5 µs median, 8 µs at most.
pub const DEFAULT_LOOK: Duration = Duration::from_millis(50);

/// The longest look [`set_racer_look`] sets.
const LONGEST_LOOK: Duration = Duration::from_secs(10);

/// [`set_racer_look`]'s value in nanoseconds.
static LOOK_NS: AtomicU64 = AtomicU64::new(DEFAULT_LOOK.as_nanos() as u64);

/// How long the racer threads (see [`super::MotionSettings::racers`]) look for work after their
/// last racer before they sleep, for the whole process: [`DEFAULT_LOOK`] unless set here (at
/// most 10 s; a thread looking already keeps the look it began with). Zero: they sleep at once,
/// and every hand-over wakes one (tens of µs out of the handing planner's time, up to a few
/// hundred). Looking yields the core to any thread that needs it, but keeps it busy when none
/// does: a process that races now and then spends less processor time with a short look, and
/// plans a little slower. Two racers on three generated
/// MotionBenchMaker cage problems, 40 rounds, looks of 50 ms against zero: a round every 100
/// ms, 2.90-3.01 s against 0.68-0.71 s of processor time over 4.7 s, planning p50 357-388
/// against 448-464 µs; rounds back to back, 1.13-1.24 against 0.62-0.68 s, p50 324-339 against
/// 384-433 µs.
pub fn set_racer_look(look: Duration) {
    LOOK_NS.store(capped(look).as_nanos() as u64, Ordering::Relaxed);
}

/// `look`, at most [`LONGEST_LOOK`].
fn capped(look: Duration) -> Duration {
    look.min(LONGEST_LOOK)
}

/// The racer threads' look (see [`set_racer_look`]).
pub fn racer_look() -> Duration {
    Duration::from_nanos(LOOK_NS.load(Ordering::Relaxed))
}

/// The nice value of a racer thread (Linux; the lowest priority of normal scheduling).
#[cfg(target_os = "linux")]
pub(super) const RACER_NICE: i32 = 19;

/// A racer thread yields its core to the thread that handed it its racer: where a thread may
/// lower its own priority (Linux, nice [`RACER_NICE`]), it does. On a free core it runs at full
/// speed; on a core it shares with its caller's planner (a machine busy with other work, or
/// `taskset` to one core) it takes almost none of that planner's time, where at equal
/// priority the two split the core and the caller's racer planned up to twice as slow, with
/// 4 ms time slices in its tail. Elsewhere, and if the system refuses, the priority stays.
fn lower_own_priority() {
    #[cfg(target_os = "linux")]
    {
        // Refused only by unusual sandboxes: the racer then runs as before.
        let _ = rustix::process::setpriority_process(Some(rustix::thread::gettid()), RACER_NICE);
    }
}

type Job = Box<dyn FnOnce() + Send>;

/// One racer thread's queue.
struct Worker {
    state: Mutex<State>,
    wake: Condvar,
    /// Jobs wait in the queue (read without the lock while looking for work).
    pending: AtomicBool,
}

struct State {
    jobs: VecDeque<Job>,
    /// The thread sleeps on `wake`: a new job must notify it.
    asleep: bool,
}

/// The process's racer threads.
pub(super) struct Racers {
    workers: Vec<&'static Worker>,
    /// The worker of the next job (round robin).
    next: AtomicUsize,
}

impl Worker {
    fn lock(&self) -> MutexGuard<'_, State> {
        // A job never panics through here (racers catch their panics); a poisoned queue is
        // still a queue.
        self.state.lock().unwrap_or_else(PoisonError::into_inner)
    }

    /// The thread's loop: look for work (for [`racer_look`]), then sleep until some comes.
    fn run(&self) {
        lower_own_priority();
        loop {
            let until = Instant::now() + racer_look();
            // Yielding, not spinning: a thread that needs this core gets it.
            while !self.pending.load(Ordering::Acquire) && Instant::now() < until {
                std::thread::yield_now();
            }
            let mut state = self.lock();
            while state.jobs.is_empty() {
                state.asleep = true;
                state = self.wake.wait(state).unwrap_or_else(PoisonError::into_inner);
            }
            state.asleep = false;
            let job = state.jobs.pop_front();
            self.pending.store(!state.jobs.is_empty(), Ordering::Release);
            drop(state);
            if let Some(job) = job {
                job();
            }
        }
    }
}

impl Racers {
    /// The racer threads, one fewer than the machine's cores (at least one), started at the
    /// first call; `None` when no thread could be started.
    pub(super) fn get() -> Option<&'static Racers> {
        static RACERS: OnceLock<Option<Racers>> = OnceLock::new();
        RACERS
            .get_or_init(|| {
                let cores = std::thread::available_parallelism().map_or(2, std::num::NonZeroUsize::get);
                let mut workers = Vec::new();
                for k in 0..cores.saturating_sub(1).max(1) {
                    let worker: &'static Worker = Box::leak(Box::new(Worker {
                        state: Mutex::new(State { jobs: VecDeque::new(), asleep: false }),
                        wake: Condvar::new(),
                        pending: AtomicBool::new(false),
                    }));
                    let started = std::thread::Builder::new().name(format!("racer-{k}")).spawn(move || worker.run());
                    if started.is_ok() {
                        workers.push(worker);
                    }
                }
                (!workers.is_empty()).then(|| Racers { workers, next: AtomicUsize::new(0) })
            })
            .as_ref()
    }

    /// Run `job` on a racer thread (in turn); a thread that is looking for work takes it with
    /// no system call here.
    pub(super) fn spawn(&self, job: impl FnOnce() + Send + 'static) {
        let k = self.next.fetch_add(1, Ordering::Relaxed) % self.workers.len();
        let worker = self.workers[k];
        let mut state = worker.lock();
        state.jobs.push_back(Box::new(job));
        worker.pending.store(true, Ordering::Release);
        if state.asleep {
            worker.wake.notify_one();
        }
    }
}

#[cfg(test)]
mod tests {
    use std::sync::mpsc;

    use super::*;

    /// Every job runs once, on a racer thread, whether the thread was looking for work or
    /// asleep when it came.
    #[test]
    fn every_job_runs_once_on_a_racer_thread() {
        let racers = Racers::get().expect("racer threads");
        let (sender, receiver) = mpsc::channel();
        for round in 0..3 {
            for k in 0..20 {
                let sender = sender.clone();
                racers.spawn(move || {
                    let name = std::thread::current().name().map(str::to_owned);
                    let _ = sender.send((round * 20 + k, name));
                });
            }
            if round == 1 {
                // Long enough for the threads to fall asleep.
                std::thread::sleep(DEFAULT_LOOK * 3);
            }
        }
        let mut seen = vec![0; 60];
        for _ in 0..60 {
            let (k, name) = receiver.recv_timeout(Duration::from_secs(10)).expect("every job runs");
            seen[k] += 1;
            assert!(name.is_some_and(|n| n.starts_with("racer-")), "job {k} on another thread");
        }
        assert!(seen.iter().all(|&n| n == 1), "{seen:?}");
    }

    /// With no look at all, every job still runs: each hand-over wakes a sleeping thread.
    #[test]
    fn jobs_run_when_threads_sleep_at_once() {
        let racers = Racers::get().expect("racer threads");
        set_racer_look(Duration::ZERO);
        let (sender, receiver) = mpsc::channel();
        for k in 0..10 {
            let sender = sender.clone();
            racers.spawn(move || {
                let _ = sender.send(k);
            });
            std::thread::sleep(Duration::from_millis(2));
        }
        let mut seen: Vec<i32> = (0..10).filter_map(|_| receiver.recv_timeout(Duration::from_secs(10)).ok()).collect();
        set_racer_look(DEFAULT_LOOK);
        seen.sort_unstable();
        assert_eq!(seen, (0..10).collect::<Vec<_>>());
    }

    /// The look is capped at 10 s.
    #[test]
    fn a_look_is_capped() {
        assert_eq!(capped(Duration::MAX), LONGEST_LOOK);
        assert_eq!(capped(Duration::from_secs(3600)), LONGEST_LOOK);
        assert_eq!(capped(Duration::from_millis(7)), Duration::from_millis(7));
        assert_eq!(capped(Duration::ZERO), Duration::ZERO);
    }
}

#[cfg(all(test, target_os = "linux"))]
mod priority {
    use std::sync::mpsc;
    use std::time::Duration;

    use super::{RACER_NICE, Racers};

    /// Every racer thread runs its racers at the lowest priority of normal scheduling; the
    /// caller's thread keeps its own.
    #[test]
    fn racer_threads_yield_to_their_caller() {
        let racers = Racers::get().expect("racer threads");
        let own = rustix::process::getpriority_process(Some(rustix::thread::gettid())).expect("own priority");
        let (sender, receiver) = mpsc::channel();
        for _ in 0..2 * racers.workers.len() {
            let sender = sender.clone();
            racers.spawn(move || {
                let _ = sender.send(rustix::process::getpriority_process(Some(rustix::thread::gettid())).ok());
            });
        }
        for _ in 0..2 * racers.workers.len() {
            let nice = receiver.recv_timeout(Duration::from_secs(10)).expect("a racer ran");
            assert_eq!(nice, Some(RACER_NICE));
        }
        assert_eq!(rustix::process::getpriority_process(Some(rustix::thread::gettid())).ok(), Some(own));
        assert_ne!(own, RACER_NICE, "the test's own thread runs at the racers' priority already");
    }
}
