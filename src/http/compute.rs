//! A small pool of dedicated threads for request-path numerical work
//! (compensation), off the async runtime.
//!
//! `spawn_blocking` per request costs two thread hand-offs (wake a blocking
//! thread, wake the runtime back), which dominated single-target
//! `/compensate` under load. Here one thread per core takes work from a
//! shared queue and drains everything queued before sleeping again, so under
//! load many requests share one wake-up.

use std::sync::mpsc::{Receiver, Sender, channel};
use std::sync::{Arc, Mutex};

use tokio::sync::oneshot;

type Job = Box<dyn FnOnce() + Send + 'static>;

/// The pool; cheap to share behind the app state.
pub struct ComputePool {
    tx: Mutex<Sender<Job>>,
}

impl ComputePool {
    /// Start `threads` threads.
    pub fn new(threads: usize) -> ComputePool {
        let (tx, rx) = channel::<Job>();
        let rx = Arc::new(Mutex::new(rx));
        for i in 0..threads.max(1) {
            let rx = rx.clone();
            std::thread::Builder::new()
                .name(format!("drawcal-compute-{i}"))
                .spawn(move || worker(rx))
                .expect("spawn a compute thread");
        }
        ComputePool { tx: Mutex::new(tx) }
    }

    /// Run `f` on a pool thread and await its result. `None` if the pool is
    /// gone or `f` panicked.
    pub async fn run<T: Send + 'static>(
        &self,
        f: impl FnOnce() -> T + Send + 'static,
    ) -> Option<T> {
        let (done, wait) = oneshot::channel();
        let job: Job = Box::new(move || {
            let r = std::panic::catch_unwind(std::panic::AssertUnwindSafe(f));
            let _ = done.send(r.ok());
        });
        self.tx.lock().ok()?.send(job).ok()?;
        wait.await.ok().flatten()
    }
}

fn worker(rx: Arc<Mutex<Receiver<Job>>>) {
    let mut batch: Vec<Job> = Vec::new();
    loop {
        {
            let Ok(guard) = rx.lock() else { return };
            match guard.recv() {
                Ok(job) => batch.push(job),
                Err(_) => return,
            }
            while batch.len() < 64 {
                match guard.try_recv() {
                    Ok(job) => batch.push(job),
                    Err(_) => break,
                }
            }
        }
        for job in batch.drain(..) {
            job();
        }
    }
}
