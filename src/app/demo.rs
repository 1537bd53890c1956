//! The built-in demo building prepared for the viewer: `synth::demo` generates it into the
//! cache on a worker thread while the viewer shows its progress. No generation logic here.

use std::path::PathBuf;
use std::sync::atomic::{AtomicU32, Ordering};
use std::sync::{Arc, Mutex};

use crossbeam_channel::Receiver;

use crate::synth::demo::{DEMO_HEIGHT, DEMO_VIEWS, DEMO_WIDTH, ensure};

/// A demo being prepared on a worker thread.
pub struct DemoPreparation {
    fraction: Arc<AtomicU32>,
    message: Arc<Mutex<String>>,
    done: Receiver<Result<PathBuf, String>>,
}

impl DemoPreparation {
    pub fn start(dir: PathBuf) -> DemoPreparation {
        let fraction = Arc::new(AtomicU32::new(0f32.to_bits()));
        let message = Arc::new(Mutex::new("starting".to_string()));
        let (tx, done) = crossbeam_channel::bounded(1);
        let (f, m) = (fraction.clone(), message.clone());
        let spawned = std::thread::Builder::new()
            .name("damage-twin-demo".into())
            .spawn(move || {
                let progress = |x: f32, text: &str| {
                    f.store(x.clamp(0.0, 1.0).to_bits(), Ordering::Relaxed);
                    if let Ok(mut slot) = m.lock() {
                        *slot = text.to_string();
                    }
                };
                let result = ensure(&dir, DEMO_VIEWS, DEMO_WIDTH, DEMO_HEIGHT, &progress)
                    .map_err(|e| format!("{e:#}"));
                let _ = tx.send(result);
            });
        if let Err(e) = spawned {
            let (tx, rx) = crossbeam_channel::bounded(1);
            let _ = tx.send(Err(format!("cannot start the demo thread: {e}")));
            return DemoPreparation {
                fraction,
                message,
                done: rx,
            };
        }
        DemoPreparation {
            fraction,
            message,
            done,
        }
    }

    pub fn fraction(&self) -> f32 {
        f32::from_bits(self.fraction.load(Ordering::Relaxed))
    }

    pub fn message(&self) -> String {
        self.message.lock().map(|m| m.clone()).unwrap_or_default()
    }

    /// The folder once ready (or why not); never blocks.
    pub fn poll(&self) -> Option<Result<PathBuf, String>> {
        self.done.try_recv().ok()
    }
}
