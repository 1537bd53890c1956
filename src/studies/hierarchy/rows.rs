//! The hierarchy study's results: one row per method, and what the study produced.

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

use crate::studies::hierarchy::config::Method;

/// One method's figures (`hierarchy-study.json` `rows`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct HierarchyRow {
    pub method: Method,
    /// Wall time of everything the method needs to make its twin (a refinement includes its
    /// coarse twin): loading, selecting, drawing hulls and training; no held-out scoring (not
    /// the trainer's final one, nor the refinement's before/after one), for every method alike.
    pub seconds: f64,
    /// Wall time per phase.
    pub phases: BTreeMap<String, f64>,
    /// The same work's CPU seconds (user + system of the process, every thread): the cost
    /// that does not grow with other processes' load. None where unreadable (and in studies
    /// saved before it was recorded).
    #[serde(default)]
    pub cpu_seconds: Option<f64>,
    /// CPU seconds per phase (the phases of `phases`; empty where unreadable).
    #[serde(default)]
    pub cpu_phases: BTreeMap<String, f64>,
    /// Held-out IoU per class at high resolution.
    pub iou: BTreeMap<String, f64>,
    /// Held-out PSNR at high resolution.
    pub psnr: f64,
    pub gaussians: usize,
}

/// What the study produced.
#[derive(Clone, Debug)]
pub struct HierarchyOutcome {
    pub rows: Vec<HierarchyRow>,
    /// Width and height of "high resolution".
    pub fine_size: (u32, u32),
}
