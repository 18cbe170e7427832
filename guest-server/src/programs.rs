//! The programs the guest runs at once, bounded as a whole: at most
//! `--max-programs` of them (`/execute`, `/setup/execute`, `/execute_windows`,
//! `/v1/exec`, MCP `run_python`), a newcomer waiting up to `--program-wait-ms` for a
//! place and then refused with [`Busy`] (a 503 naming the limit); and one interpreter
//! memory pool of `--program-memory-mib` that every interpreter run draws from
//! beside its own 256 MiB ([`arena_script::MemoryPool`]), so that the programs
//! together hold at most that much in values, however many were sent.
//!
//! A place is held by the work itself ([`Place`] moves into the backend call), not by
//! the request: a request that timed out or went away keeps its place until its
//! program has really stopped.

use std::sync::Arc;
use std::time::Duration;

use arena_script::MemoryPool;
use tokio::sync::{OwnedSemaphorePermit, Semaphore};

use crate::config::ServerConfig;

/// The guest's bound on running programs.
#[derive(Debug)]
pub struct Programs {
    places: Arc<Semaphore>,
    max: u32,
    wait: Duration,
    memory: Arc<MemoryPool>,
}

/// One running program's place; dropping it frees the place.
#[derive(Debug)]
pub struct Place {
    _permit: OwnedSemaphorePermit,
    memory: Arc<MemoryPool>,
}

impl Place {
    /// The interpreter memory the program shares with the others.
    pub fn memory(&self) -> Arc<MemoryPool> {
        Arc::clone(&self.memory)
    }
}

/// No place came free in time.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error(
    "{max} programs are running already, the most this guest runs at once (--max-programs {max}); none finished within {waited_ms} ms; try again later"
)]
pub struct Busy {
    pub max: u32,
    pub waited_ms: u64,
}

impl Programs {
    /// At most `max` programs at once, a newcomer waiting up to `wait`, sharing
    /// `memory_bytes` of interpreter memory.
    pub fn new(max: u32, wait: Duration, memory_bytes: usize) -> Programs {
        let max = max.max(1);
        Programs {
            places: Arc::new(Semaphore::new(max as usize)),
            max,
            wait,
            memory: Arc::new(MemoryPool::new(memory_bytes)),
        }
    }

    /// The bounds `config` names.
    pub fn from_config(config: &ServerConfig) -> Programs {
        let bytes = usize::try_from(config.program_memory_mib.saturating_mul(1 << 20)).unwrap_or(usize::MAX);
        Programs::new(config.max_programs, Duration::from_millis(config.program_wait_ms), bytes)
    }

    /// A place for one program, waiting for one up to the configured time.
    ///
    /// # Errors
    ///
    /// [`Busy`] when none came free in time.
    pub async fn admit(&self) -> Result<Place, Busy> {
        let busy = || Busy { max: self.max, waited_ms: u64::try_from(self.wait.as_millis()).unwrap_or(u64::MAX) };
        match tokio::time::timeout(self.wait, Arc::clone(&self.places).acquire_owned()).await {
            Ok(Ok(permit)) => Ok(Place { _permit: permit, memory: Arc::clone(&self.memory) }),
            // The semaphore is never closed; a closed one admits nobody either.
            Ok(Err(_)) | Err(_) => Err(busy()),
        }
    }

    /// The shared interpreter memory.
    pub fn memory(&self) -> &MemoryPool {
        &self.memory
    }

    /// How many programs run now.
    pub fn running(&self) -> usize {
        self.max as usize - self.places.available_permits()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[tokio::test]
    async fn a_program_past_the_limit_waits_then_is_refused_naming_it() {
        let programs = Programs::new(2, Duration::from_millis(50), 1 << 20);
        let first = programs.admit().await.expect("a place");
        let _second = programs.admit().await.expect("a place");
        assert_eq!(programs.running(), 2);
        let busy = programs.admit().await.expect_err("no third place");
        assert_eq!(busy, Busy { max: 2, waited_ms: 50 });
        assert!(busy.to_string().contains("--max-programs 2"), "{busy}");
        // A waiting program gets the place a finished one gives back.
        let waiting = programs.admit();
        drop(first);
        assert!(waiting.await.is_ok());
    }
}
