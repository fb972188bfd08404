//! The compute pool: a bounded queue of validated batches and dedicated threads (not the async runtime's)
//! that evaluate them. With dynamic batching a thread merges the queued requests for the same model version
//! (up to `max_batch_size` states, waiting at most `max_queue_delay` for more) into one evaluation and
//! splits the answer. A full queue refuses new work with `RESOURCE_EXHAUSTED`; work whose caller left or
//! whose deadline passed is dropped unevaluated.

use crate::loaded_model::{BatchResult, LoadedModel};
use crate::metrics::Metrics;
use crate::settings::ComputeSettings;
use crate::validate::ValidBatch;
use fastrack_valuefn::runtime::Evaluation;
use std::collections::VecDeque;
use std::sync::{Arc, Condvar, Mutex, MutexGuard};
use std::time::Instant;
use tokio::sync::oneshot;
use tonic::Status;

type Reply = Result<(BatchResult, ValidBatch), Status>;

struct Job {
    model: Arc<LoadedModel>,
    batch: ValidBatch,
    reply: oneshot::Sender<Reply>,
    enqueued: Instant,
    deadline: Option<Instant>,
}

#[derive(Default)]
struct Queue {
    jobs: VecDeque<Job>,
    items: usize,
    closed: bool,
}

struct Shared {
    queue: Mutex<Queue>,
    wake: Condvar,
    settings: ComputeSettings,
    metrics: Arc<Metrics>,
}

/// The pool; [`Scheduler::shutdown`] finishes queued work and joins the threads.
pub struct Scheduler {
    shared: Arc<Shared>,
    threads: Mutex<Vec<std::thread::JoinHandle<()>>>,
}

impl Scheduler {
    /// Starts `settings.threads` compute threads.
    pub fn start(settings: ComputeSettings, metrics: Arc<Metrics>) -> std::io::Result<Self> {
        let shared = Arc::new(Shared { queue: Mutex::new(Queue::default()), wake: Condvar::new(), settings, metrics });
        let threads = (0..settings.threads)
            .map(|i| {
                let shared = Arc::clone(&shared);
                std::thread::Builder::new().name(format!("fastrack-compute-{i}")).spawn(move || shared.work())
            })
            .collect::<std::io::Result<Vec<_>>>()?;
        Ok(Self { shared, threads: Mutex::new(threads) })
    }

    /// Queues `batch` for `model` and waits for its answer. `RESOURCE_EXHAUSTED` at once when the queue is
    /// full, `DEADLINE_EXCEEDED` if `deadline` passes before a thread takes it.
    pub async fn evaluate(&self, model: &Arc<LoadedModel>, batch: ValidBatch, deadline: Option<Instant>) -> Reply {
        let (reply, answer) = oneshot::channel();
        {
            let mut queue = self.shared.lock();
            if queue.closed {
                return Err(Status::unavailable("the server is shutting down"));
            }
            let capacity = self.shared.settings.queue_capacity;
            if queue.items > 0 && queue.items + batch.n > capacity {
                self.shared.metrics.shed();
                return Err(Status::resource_exhausted(format!(
                    "server overloaded: {} states are waiting for evaluation (queue capacity {capacity}); retry with backoff",
                    queue.items
                )));
            }
            queue.items += batch.n;
            self.shared.metrics.set_queued_items(queue.items);
            queue.jobs.push_back(Job { model: Arc::clone(model), batch, reply, enqueued: Instant::now(), deadline });
        }
        self.shared.wake.notify_one();
        answer.await.map_err(|_| Status::internal("the compute pool dropped the request"))?
    }

    /// Stops taking work, lets the threads finish what is queued and joins them.
    pub fn shutdown(&self) {
        self.shared.lock().closed = true;
        self.shared.wake.notify_all();
        let threads = std::mem::take(&mut *self.threads.lock().unwrap_or_else(|e| e.into_inner()));
        for thread in threads {
            let _ = thread.join();
        }
    }
}

impl Drop for Scheduler {
    fn drop(&mut self) {
        self.shutdown();
    }
}

impl Shared {
    fn lock(&self) -> MutexGuard<'_, Queue> {
        self.queue.lock().unwrap_or_else(|e| e.into_inner())
    }

    fn work(&self) {
        while let Some(group) = self.next_group() {
            self.run(group);
        }
    }

    /// Removes and returns the first job still worth running, answering expired ones.
    fn pop_live(queue: &mut Queue, now: Instant) -> Option<Job> {
        while let Some(job) = queue.jobs.pop_front() {
            queue.items -= job.batch.n;
            if job.reply.is_closed() {
                continue;
            }
            if job.deadline.is_some_and(|d| d <= now) {
                let _ =
                    job.reply.send(Err(Status::deadline_exceeded("the deadline passed while the request was queued")));
                continue;
            }
            return Some(job);
        }
        None
    }

    /// Moves queued jobs of `model` into `group` while they fit in `max` items.
    fn take_matching(queue: &mut Queue, model: &Arc<LoadedModel>, group: &mut Vec<Job>, items: &mut usize, max: usize) {
        let mut rest = VecDeque::with_capacity(queue.jobs.len());
        for job in queue.jobs.drain(..) {
            if Arc::ptr_eq(&job.model, model) && *items + job.batch.n <= max && !job.reply.is_closed() {
                *items += job.batch.n;
                queue.items -= job.batch.n;
                group.push(job);
            } else {
                rest.push_back(job);
            }
        }
        queue.jobs = rest;
    }

    /// Blocks until there is work (`None` once closed and drained) and gathers one evaluation's worth.
    fn next_group(&self) -> Option<Vec<Job>> {
        let mut queue = self.lock();
        let first = loop {
            if let Some(job) = Self::pop_live(&mut queue, Instant::now()) {
                break job;
            }
            if queue.closed {
                return None;
            }
            queue = self.wake.wait(queue).unwrap_or_else(|e| e.into_inner());
        };
        let model = Arc::clone(&first.model);
        let mut items = first.batch.n;
        let until = first.enqueued + self.settings.max_queue_delay;
        let mut group = vec![first];
        if self.settings.dynamic_batching {
            let max = self.settings.max_batch_size;
            loop {
                Self::take_matching(&mut queue, &model, &mut group, &mut items, max);
                let now = Instant::now();
                if items >= max || queue.closed || now >= until {
                    break;
                }
                queue = self.wake.wait_timeout(queue, until - now).unwrap_or_else(|e| e.into_inner()).0;
            }
        }
        self.metrics.set_queued_items(queue.items);
        Some(group)
    }

    fn run(&self, mut group: Vec<Job>) {
        let start = Instant::now();
        for job in &group {
            self.metrics.queued(start - job.enqueued);
        }
        let model = Arc::clone(&group[0].model);
        let items: usize = group.iter().map(|j| j.batch.n).sum();
        let result = if group.len() == 1 {
            model.compute(&group[0].batch.states, &group[0].batch.params)
        } else {
            let states: Vec<f32> = group.iter().flat_map(|j| j.batch.states.iter().copied()).collect();
            let params: Vec<f32> = group.iter().flat_map(|j| j.batch.params.iter().copied()).collect();
            model.compute(&states, &params)
        };
        self.metrics.evaluation(items, start.elapsed());
        let outputs = match result {
            Ok(outputs) => outputs,
            Err(status) => {
                for job in group {
                    let _ = job.reply.send(Err(status.clone()));
                }
                return;
            }
        };
        let split = if group.len() == 1 { vec![outputs] } else { split(outputs, &group, &model) };
        for (job, outputs) in group.drain(..).zip(split) {
            let result = model.result(outputs, &job.batch);
            let _ = job.reply.send(result.map(|result| (result, job.batch)));
        }
    }
}

/// Cuts a merged evaluation back into one per job, in order.
fn split(merged: Evaluation, group: &[Job], model: &LoadedModel) -> Vec<Evaluation> {
    let (ns, nc) = (model.space.n_state(), model.manifest.n_control());
    let mut offset = 0;
    group
        .iter()
        .map(|job| {
            let (a, b) = (offset, offset + job.batch.n);
            offset = b;
            Evaluation {
                value: merged.value[a..b].to_vec(),
                grad: merged.grad[a * ns..b * ns].to_vec(),
                control: merged.control[a * nc..b * nc].to_vec(),
            }
        })
        .collect()
}
