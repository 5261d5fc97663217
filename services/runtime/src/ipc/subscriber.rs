//! Typed subscribers: take samples, count them, await the next one.

use std::time::Duration;

use skymesh_ipc_types::{Sample, Topic};

use super::{ipc_err, Bus, IpcError, ReceiveCounts, SocketWait, Svc};

impl Bus {
    /// A subscriber on `topic`: awaited with `recv` (inside a tokio runtime) or
    /// polled with `try_recv`.
    pub fn subscriber<T: Sample>(&self, topic: &Topic) -> Result<Subscriber<T>, IpcError> {
        self.subscriber_counted_as(topic, &topic.name)
    }

    /// A subscriber whose metrics carry `topic="<family>"` (see
    /// [`Bus::publisher_counted_as`]); gaps are still counted per port.
    pub fn subscriber_counted_as<T: Sample>(
        &self,
        topic: &Topic,
        family: &str,
    ) -> Result<Subscriber<T>, IpcError> {
        let pubsub = self.open_pubsub::<T>(topic)?;
        let event = self.open_event(topic)?;
        let port = pubsub
            .subscriber_builder()
            .create()
            .map_err(|e| ipc_err("create subscriber", &topic.name, e))?;
        let socket = SocketWait::new(event, &topic.name)?;
        Ok(Subscriber {
            socket,
            port,
            counts: ReceiveCounts::new(self.stats(), family),
            topic: topic.name.clone(),
            _bus: self.clone(),
        })
    }
}

/// Takes one pending sample from `port` as a copy.
fn take<T: Sample>(
    port: &iceoryx2::port::subscriber::Subscriber<Svc, T, ()>,
    topic: &str,
) -> Result<Option<T>, IpcError> {
    let Some(sample) = port.receive().map_err(|e| ipc_err("receive", topic, e))? else {
        return Ok(None);
    };
    let value: T = *sample.payload();
    drop(sample);
    Ok(Some(value))
}

/// Receives samples of one type from one topic.
pub struct Subscriber<T: Sample> {
    /// The topic's event, which the receives wait on.
    socket: SocketWait,
    port: iceoryx2::port::subscriber::Subscriber<Svc, T, ()>,
    counts: ReceiveCounts,
    topic: String,
    _bus: Bus,
}

impl<T: Sample> core::fmt::Debug for Subscriber<T> {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("Subscriber")
            .field("topic", &self.topic)
            .finish()
    }
}

impl<T: Sample> Subscriber<T> {
    /// Takes one pending sample without waiting.
    pub fn try_recv(&self) -> Result<Option<T>, IpcError> {
        let value = take(&self.port, &self.topic)?;
        if let Some(v) = &value {
            self.account(v);
        }
        Ok(value)
    }

    /// Takes one pending sample without waiting and hands it to `read` where it lies
    /// in shared memory (no copy: for large samples).
    pub fn try_recv_with<R>(&self, read: impl FnOnce(&T) -> R) -> Result<Option<R>, IpcError> {
        let Some(sample) = self
            .port
            .receive()
            .map_err(|e| ipc_err("receive", &self.topic, e))?
        else {
            return Ok(None);
        };
        self.account(sample.payload());
        Ok(Some(read(sample.payload())))
    }

    fn account(&self, value: &T) {
        let h = value.header();
        self.counts.count(h);
    }

    /// Declares that this subscriber wants only the newest value (it reads with
    /// [`Subscriber::latest`] at its own rate, slower than the publisher's), so
    /// samples overwritten in its buffer before it looked are by design and are not
    /// counted in `skymesh_topic_samples_lost_total`.
    pub fn set_newest_only(&mut self) {
        self.counts.newest_only = true;
    }

    /// Waits for the next sample. Cancel-safe: dropping the future loses nothing.
    /// A sample published quietly ([`super::Publisher::publish_quiet`]) is received with
    /// the next notified one (or by [`Subscriber::try_recv`]); a receive that found
    /// the queue empty waits for a notification without looking again.
    pub async fn recv(&mut self) -> Result<T, IpcError> {
        self.settle()?;
        loop {
            if let Some(v) = self.socket.notes.look(|| self.try_recv())? {
                return Ok(v);
            }
            self.wait_readable().await?;
        }
    }

    /// Waits for the next sample and hands it to `read` in place (see
    /// [`Subscriber::try_recv_with`]). Cancel-safe.
    pub async fn recv_with<R>(&mut self, mut read: impl FnMut(&T) -> R) -> Result<R, IpcError> {
        self.settle()?;
        loop {
            if let Some(r) = self.socket.notes.look(|| self.try_recv_with(&mut read))? {
                return Ok(r);
            }
            self.wait_readable().await?;
        }
    }

    /// Consumes the last wake-up's notification (see `Notifications` in `wait`).
    fn settle(&self) -> Result<(), IpcError> {
        self.socket.settle_async(&self.topic)
    }

    /// Waits until the topic's event fires (a publisher notified).
    async fn wait_readable(&mut self) -> Result<(), IpcError> {
        self.socket.wait_async(&self.topic).await
    }

    /// Drains everything pending and returns the newest sample, if any.
    pub fn latest(&self) -> Result<Option<T>, IpcError> {
        let mut newest = None;
        while let Some(v) = self.try_recv()? {
            newest = Some(v);
        }
        Ok(newest)
    }

    /// Waits up to `timeout` for the next sample.
    pub async fn recv_timeout(&mut self, timeout: Duration) -> Result<Option<T>, IpcError> {
        match tokio::time::timeout(timeout, self.recv()).await {
            Ok(r) => r.map(Some),
            Err(_) => Ok(None),
        }
    }

    pub fn topic(&self) -> &str {
        &self.topic
    }
}
