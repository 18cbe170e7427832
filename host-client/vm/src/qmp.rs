//! The QMP control socket of one VM, through the `qapi` crate: commands with
//! deadlines, the monitor's text commands (`savevm`, `loadvm`), and the VM's
//! events (reset, shutdown) as names on a broadcast channel.
//!
//! QEMU serves QMP here on a Unix socket (`-qmp unix:`, see `qemu.rs`), so VMs
//! are driven from a Linux host; elsewhere [`Qmp::connect`] says so at once.

use std::path::Path;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use futures_util::StreamExt;
use qapi::futures::{QapiService, QmpStreamTokio};
use qapi::qmp;
use tokio::io::WriteHalf;
use tokio::sync::broadcast;
use tokio::time::Instant;

use super::{check_snapshot_name, known_list, parse_snapshot_list, VmError};

/// How long saving or loading a snapshot may take (memory of a large guest).
pub(crate) const SNAPSHOT_TIMEOUT: Duration = Duration::from_secs(600);

/// The monitor's socket.
#[cfg(unix)]
type Socket = tokio::net::UnixStream;
/// Never connected ([`open`] refuses): a stand-in so that the types stay the same.
#[cfg(not(unix))]
type Socket = tokio::net::TcpStream;

type Service = QapiService<QmpStreamTokio<WriteHalf<Socket>>>;

/// Connects to the monitor's socket at `path`.
#[cfg(unix)]
async fn open(path: &Path) -> std::io::Result<Socket> {
    Socket::connect(path).await
}

/// Refuses: QEMU's monitor is a Unix socket, driven from a Linux host.
#[cfg(not(unix))]
async fn open(path: &Path) -> std::io::Result<Socket> {
    Err(std::io::Error::new(
        std::io::ErrorKind::Unsupported,
        format!("{} is a Unix socket: VMs are driven from a Linux host", path.display()),
    ))
}

/// One negotiated QMP connection.
pub struct Qmp {
    service: Service,
    /// Held by one command from before it is sent until it ends, so that a
    /// failed call is known before the next one starts (see [`Qmp::execute`]).
    turn: Arc<tokio::sync::Mutex<()>>,
    /// Why the connection can carry no more commands, once it cannot.
    broken: Arc<Mutex<Option<String>>>,
    /// The `reason` of the last `SHUTDOWN` event (`guest-shutdown`, `host-signal`, ...).
    shutdown: Arc<Mutex<Option<String>>>,
    events: broadcast::Sender<String>,
    reader: tokio::task::JoinHandle<()>,
    /// Deadline of one command.
    pub timeout: Duration,
}

impl std::fmt::Debug for Qmp {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Qmp").field("timeout", &self.timeout).finish_non_exhaustive()
    }
}

impl Drop for Qmp {
    fn drop(&mut self) {
        self.reader.abort();
    }
}

impl Qmp {
    /// Connects to the socket at `path`, trying again until `within` has passed
    /// (QEMU creates it a moment after it starts), and negotiates capabilities.
    ///
    /// # Errors
    ///
    /// [`VmError::Qmp`] when no connection is made in time.
    pub async fn connect(path: &Path, within: Duration) -> Result<Qmp, VmError> {
        let started = Instant::now();
        // A monitor serves one client at a time and keeps later ones waiting
        // for its greeting: the greeting and negotiation get a deadline. QEMU
        // also greets only once its main loop runs, which with `-loadvm` is
        // after the whole snapshot is loaded: the deadline is what is left of
        // `within`, and at least 10 s.
        let stream = loop {
            let greeting = within.saturating_sub(started.elapsed()).max(Duration::from_secs(10));
            let attempt = async { QmpStreamTokio::open(open(path).await?).await?.negotiate().await };
            match tokio::time::timeout(greeting, attempt).await {
                Ok(Ok(stream)) => break stream,
                Ok(Err(err)) if err.kind() == std::io::ErrorKind::Unsupported => {
                    return Err(qmp_error(&format!("connecting to {}", path.display()), err))
                }
                Ok(Err(err)) if started.elapsed() < within => {
                    tracing::trace!(socket = %path.display(), error = %err, "QMP socket not ready yet");
                    tokio::time::sleep(Duration::from_millis(50)).await;
                }
                Ok(Err(err)) => return Err(qmp_error(&format!("connecting to {}", path.display()), err)),
                Err(_) => {
                    return Err(qmp_error(
                        &format!("connecting to {}", path.display()),
                        format!("no greeting in {} s (another client holds this monitor?)", greeting.as_secs()),
                    ))
                }
            }
        };
        let (service, mut events) = stream.into_parts();
        let (tx, _) = broadcast::channel(64);
        let sender = tx.clone();
        let broken = Arc::new(Mutex::new(None));
        let reader_broken = Arc::clone(&broken);
        let shutdown = Arc::new(Mutex::new(None));
        let reader_shutdown = Arc::clone(&shutdown);
        // The reader delivers command answers to `service` and events to the channel.
        let reader = tokio::spawn(async move {
            let mut errors = 0u32;
            while let Some(item) = events.next().await {
                match item {
                    Ok(event) => {
                        let value = serde_json::to_value(&event).unwrap_or_default();
                        let name = value.get("event").and_then(|e| e.as_str()).unwrap_or("UNKNOWN").to_owned();
                        if name == "SHUTDOWN" {
                            let reason = value.pointer("/data/reason").and_then(|r| r.as_str()).unwrap_or("unknown");
                            if let Ok(mut slot) = reader_shutdown.lock() {
                                *slot = Some(reason.to_owned());
                            }
                        }
                        tracing::debug!(event = %name, "QMP event");
                        let _ = sender.send(name);
                    }
                    // A message the schema does not know (an event of another QEMU
                    // version) is skipped: the codec has consumed its line.
                    Err(err) => {
                        tracing::debug!(error = %err, kind = ?err.kind(), "QMP message not understood");
                        errors += 1;
                        if errors > 1000 {
                            break;
                        }
                    }
                }
            }
            mark_broken(&reader_broken, "QEMU closed the monitor connection");
            let _ = sender.send(CLOSED.to_owned());
        });
        Ok(Qmp {
            service,
            turn: Arc::default(),
            broken,
            shutdown,
            events: tx,
            reader,
            timeout: Duration::from_secs(30),
        })
    }

    /// Why QEMU last said it shuts down (the `reason` of its `SHUTDOWN` event:
    /// `guest-shutdown` when the guest powered off, `host-...` when the host asked).
    pub fn shutdown_reason(&self) -> Option<String> {
        self.shutdown.lock().ok().and_then(|slot| slot.clone())
    }

    /// The VM's events from now on, by name (`RESET`, `SHUTDOWN`, `STOP`, ...;
    /// [`CLOSED`] when the connection ends).
    pub fn events(&self) -> broadcast::Receiver<String> {
        self.events.subscribe()
    }

    async fn execute<C>(&self, command: C, timeout: Duration) -> Result<C::Ok, VmError>
    where
        C: qapi::qmp::QmpCommand + qapi::Command + Send + 'static,
        C::Ok: Send + 'static,
    {
        let name = <C as qapi::Command>::NAME;
        // The call runs as its own task, so that a deadline here (or a caller's
        // own timeout around this) never drops it midway. QEMU's monitor here
        // answers without command ids, so qapi gives every command id 0 and
        // files it as pending until its answer comes; a second command filed
        // while one is pending panics inside qapi ("QAPI duplicate command id
        // 0") and poisons its lock. Two ways leave one pending: a call dropped
        // after sending, and a send that fails because QEMU is going away
        // (qapi files the command before writing it and does not take it back).
        // So each call holds `turn` from before it is filed until it ends, and
        // one that fails on the connection marks it broken under that turn:
        // the next call sees the mark and never reaches qapi. A call left
        // running past its deadline keeps its turn; later ones wait behind it
        // and meet their own deadlines.
        let turn = Arc::clone(&self.turn);
        let broken = Arc::clone(&self.broken);
        let service_call = self.service.execute(command);
        let call = tokio::spawn(async move {
            let _turn = turn.lock_owned().await;
            if let Some(why) = broken.lock().map_err(|_| "a monitor call failed".to_owned())?.clone() {
                return Err(why);
            }
            match service_call.await {
                Ok(ok) => Ok(ok),
                // An answer this schema cannot read: the connection is still good.
                Err(qapi::ExecuteError::Io(err)) if err.kind() != std::io::ErrorKind::InvalidData => {
                    let why = format!("the monitor connection failed: {err}");
                    mark_broken(&broken, &why);
                    Err(why)
                }
                Err(err) => Err(err.to_string()),
            }
        });
        match tokio::time::timeout(timeout, call).await {
            Ok(Ok(Ok(ok))) => Ok(ok),
            Ok(Ok(Err(err))) => Err(qmp_error(name, err)),
            Ok(Err(err)) => {
                mark_broken(&self.broken, "a monitor call ended abnormally");
                Err(qmp_error(name, format!("the call ended abnormally: {err}")))
            }
            Err(_) => Err(qmp_error(name, format!("no answer in {} s", timeout.as_secs()))),
        }
    }

    /// A monitor (HMP) command line; its printed output. QEMU reports many
    /// HMP failures only as text starting with `Error:`, which is an error here.
    ///
    /// # Errors
    ///
    /// [`VmError::Qmp`] on a failed command or an `Error:` output.
    pub async fn hmp(&self, line: &str, timeout: Duration) -> Result<String, VmError> {
        let out = self
            .execute(qmp::human_monitor_command { command_line: line.to_owned(), cpu_index: None }, timeout)
            .await?;
        if let Some(error) = out.lines().find(|l| l.trim_start().starts_with("Error")) {
            return Err(qmp_error(line, error.trim()));
        }
        Ok(out)
    }

    /// Saves the running VM's memory and disk as snapshot `name` (replacing one
    /// of that name); how long it took.
    ///
    /// # Errors
    ///
    /// A name QEMU's monitor cannot take, or [`VmError::Qmp`] with QEMU's reason.
    pub async fn save_snapshot(&self, name: &str) -> Result<Duration, VmError> {
        check_snapshot_name(name)?;
        let started = Instant::now();
        self.hmp(&format!("savevm {name}"), SNAPSHOT_TIMEOUT).await?;
        Ok(started.elapsed())
    }

    /// The snapshots in the VM's disks, by name.
    ///
    /// # Errors
    ///
    /// [`VmError::Qmp`].
    pub async fn snapshots(&self) -> Result<Vec<String>, VmError> {
        Ok(parse_snapshot_list(&self.hmp("info snapshots", self.timeout).await?))
    }

    /// Puts the VM back to snapshot `name` (memory and disk) and lets it run;
    /// how long the restore took. `disk` names the VM's disk in the error.
    ///
    /// # Errors
    ///
    /// [`VmError::NoSnapshot`] naming the snapshots there are, or [`VmError::Qmp`].
    pub async fn restore_snapshot(&self, name: &str, disk: &Path) -> Result<Duration, VmError> {
        check_snapshot_name(name)?;
        let known = self.snapshots().await?;
        if !known.iter().any(|k| k == name) {
            return Err(VmError::NoSnapshot {
                name: name.to_owned(),
                disk: disk.to_owned(),
                known: known_list(&known),
            });
        }
        let started = Instant::now();
        self.hmp(&format!("loadvm {name}"), SNAPSHOT_TIMEOUT).await?;
        if !self.status().await?.0 {
            self.cont().await?;
        }
        Ok(started.elapsed())
    }

    /// Whether the VM's CPUs run, and QEMU's name for its state.
    ///
    /// # Errors
    ///
    /// [`VmError::Qmp`].
    pub async fn status(&self) -> Result<(bool, String), VmError> {
        let info = self.execute(qmp::query_status {}, self.timeout).await?;
        let state =
            serde_json::to_value(info.status).ok().and_then(|v| v.as_str().map(str::to_owned)).unwrap_or_default();
        Ok((info.running, state))
    }

    /// Writes the VM's display as a PNG file (QEMU 7.1 and later).
    ///
    /// # Errors
    ///
    /// [`VmError::Qmp`].
    pub async fn screendump(&self, png: &Path) -> Result<(), VmError> {
        let command = qmp::screendump {
            filename: png.display().to_string(),
            device: None,
            head: None,
            format: Some(qmp::ImageFormat::png),
        };
        self.execute(command, self.timeout).await?;
        Ok(())
    }

    /// Presses the VM's power button (ACPI): the guest shuts itself down.
    ///
    /// # Errors
    ///
    /// [`VmError::Qmp`].
    pub async fn powerdown(&self) -> Result<(), VmError> {
        self.execute(qmp::system_powerdown {}, self.timeout).await?;
        Ok(())
    }

    /// Ends QEMU at once.
    ///
    /// # Errors
    ///
    /// [`VmError::Qmp`] (the connection often closes before the answer; callers
    /// wait for the process instead).
    pub async fn quit(&self) -> Result<(), VmError> {
        self.execute(qmp::quit {}, self.timeout).await?;
        Ok(())
    }

    /// Resumes the VM's CPUs (after `loadvm` of a snapshot taken while paused).
    ///
    /// # Errors
    ///
    /// [`VmError::Qmp`].
    pub async fn cont(&self) -> Result<(), VmError> {
        self.execute(qmp::cont {}, self.timeout).await?;
        Ok(())
    }
}

/// The event name sent when the QMP connection ends.
pub const CLOSED: &str = "QMP_CLOSED";

/// Records the first reason the connection cannot carry commands.
fn mark_broken(broken: &Mutex<Option<String>>, why: &str) {
    if let Ok(mut slot) = broken.lock() {
        slot.get_or_insert_with(|| why.to_owned());
    }
}

fn qmp_error(what: &str, err: impl std::fmt::Display) -> VmError {
    VmError::Qmp { what: what.to_owned(), message: err.to_string() }
}

// A Unix socket monitor, as QEMU's.
#[cfg(all(test, unix))]
mod tests {
    use super::*;
    use tokio::io::{AsyncBufReadExt, AsyncWriteExt, BufReader};

    /// A monitor that greets, accepts the capabilities, then hangs up on the
    /// first command: that command fails, and every later one fails at once
    /// naming why, without reaching qapi (whose pending command 0 would make
    /// the next one panic).
    #[tokio::test]
    async fn a_monitor_that_hangs_up_fails_every_later_command_without_a_panic() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("qmp.sock");
        let listener = tokio::net::UnixListener::bind(&path).unwrap();
        let server = tokio::spawn(async move {
            let (stream, _) = listener.accept().await.unwrap();
            let (read, mut write) = stream.into_split();
            let mut lines = BufReader::new(read).lines();
            write
                .write_all(b"{\"QMP\": {\"version\": {\"qemu\": {\"micro\": 0, \"minor\": 2, \"major\": 8}, \"package\": \"\"}, \"capabilities\": []}}\r\n")
                .await
                .unwrap();
            let negotiate = lines.next_line().await.unwrap().unwrap_or_default();
            assert!(negotiate.contains("qmp_capabilities"), "{negotiate}");
            write.write_all(b"{\"return\": {}}\r\n").await.unwrap();
            let first = lines.next_line().await.unwrap().unwrap_or_default();
            first
        });
        let qmp = Qmp::connect(&path, Duration::from_secs(5)).await.unwrap();
        let first = qmp.status().await.unwrap_err().to_string();
        let sent = server.await.unwrap();
        assert!(sent.contains("query-status"), "{sent}");
        assert!(first.contains("query-status"), "{first}");
        for _ in 0..3 {
            let later = qmp.quit().await.unwrap_err().to_string();
            assert!(later.contains("quit") && later.contains("monitor connection"), "{later}");
        }
    }
}
