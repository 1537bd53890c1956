//! An ONNX segmentation model run by tract (pure Rust, no native runtime): read once, its input
//! and output checked against what segmentation feeds and reads (`[1, 3, H, W]` in,
//! `[1, C, H, W]` out), and a plan optimised for each input size on first use (a photo set has
//! one or two tile sizes, so few plans; tract optimises for concrete shapes).

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};

use tract_onnx::prelude::*;
use tract_onnx::tract_hir::infer::GenericFactoid;

use crate::segment::SegmentError;
use crate::segment::error::one_line;

/// The largest model file read (the shared crack model is 19 MB; segmentation networks with
/// big encoders reach a few hundred).
const MAX_MODEL_BYTES: u64 = 2 << 30;

type Plan = Arc<TypedRunnableModel>;

/// The input side the model is typed at when opened, to check its output (a multiple of 16 and
/// of 32, as segmentation networks need).
const PROBE_SIDE: u32 = 256;

/// A loaded model with its output channel count.
pub struct SegmentModel {
    path: PathBuf,
    graph: InferenceModel,
    channels: usize,
    /// Optimised plans by input (width, height).
    plans: Mutex<HashMap<(u32, u32), Plan>>,
}

impl std::fmt::Debug for SegmentModel {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SegmentModel")
            .field("path", &self.path)
            .field("channels", &self.channels)
            .finish_non_exhaustive()
    }
}

/// A shape as the model file states it (`?` for a free dimension).
fn shape_text(fact: &InferenceFact) -> String {
    let dims: Vec<String> = fact.shape.dims().map(|d| format!("{d:?}")).collect();
    let open = if fact.shape.is_open() { ", .." } else { "" };
    format!("[{}{open}]", dims.join(", "))
}

/// Dimension `index` of `fact` when the file fixes it.
fn known_dim(fact: &InferenceFact, index: usize) -> Option<i64> {
    fact.shape.dims().nth(index).and_then(|d| match d {
        GenericFactoid::Only(dim) => dim.to_i64().ok(),
        GenericFactoid::Any => None,
    })
}

impl SegmentModel {
    /// Reads the ONNX model at `path`, which must give `channels` output channels (one per class
    /// it is read as). A model with another number of inputs, an input that is not 3-channel
    /// NCHW, or an output that is not 4-D with `channels` channels is refused, naming the shapes.
    pub fn open(path: &Path, channels: usize) -> Result<SegmentModel, SegmentError> {
        let model_error = |message: String| SegmentError::Model {
            path: path.to_path_buf(),
            message,
        };
        let bytes = crate::scene::files::read_regular(path, MAX_MODEL_BYTES)?;
        let graph = tract_onnx::onnx()
            .model_for_read(&mut bytes.as_slice())
            .map_err(|e| model_error(one_line(e)))?;
        let shape_error = |message: String| SegmentError::Shape {
            path: path.to_path_buf(),
            message,
        };
        let inputs = graph.input_outlets().map_or(0, |o| o.len());
        let outputs = graph.output_outlets().map_or(0, |o| o.len());
        if inputs != 1 || outputs == 0 {
            return Err(shape_error(format!(
                "the model has {inputs} inputs and {outputs} outputs; segmentation feeds one \
                 image [1, 3, H, W] and reads the first output [1, C, H, W]"
            )));
        }
        let input = graph
            .input_fact(0)
            .map_err(|e| model_error(one_line(e)))?
            .clone();
        let rank_ok = input.shape.is_open() || input.shape.dims().count() == 4;
        if !rank_ok || known_dim(&input, 1).is_some_and(|c| c != 3) {
            return Err(shape_error(format!(
                "the model's input is {}; segmentation feeds an RGB image as [1, 3, H, W]",
                shape_text(&input)
            )));
        }
        let output = graph
            .output_fact(0)
            .map_err(|e| model_error(one_line(e)))?
            .clone();
        let output_rank_ok = output.shape.is_open() || output.shape.dims().count() == 4;
        let output_channels = known_dim(&output, 1);
        if !output_rank_ok || output_channels.is_some_and(|c| c != channels as i64) {
            return Err(shape_error(format!(
                "the model's output is {}; segmentation reads [1, {channels}, H, W] ({channels} \
                 class channel{})",
                shape_text(&output),
                if channels == 1 { "" } else { "s" }
            )));
        }
        let model = SegmentModel {
            path: path.to_path_buf(),
            graph,
            channels,
            plans: Mutex::new(HashMap::new()),
        };
        // A file may leave the channel count to shape inference: typing the graph at a probe
        // size finds it now, not at the first photo.
        model.typed(PROBE_SIDE, PROBE_SIDE)?;
        Ok(model)
    }

    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Output channels (classes) per pixel.
    pub fn channels(&self) -> usize {
        self.channels
    }

    /// The plan for `width × height` inputs, optimised on first use.
    fn plan(&self, width: u32, height: u32) -> Result<Plan, SegmentError> {
        if let Ok(plans) = self.plans.lock()
            && let Some(plan) = plans.get(&(width, height))
        {
            return Ok(plan.clone());
        }
        // Optimised outside the lock: two threads may both build the first plan of a size
        // (seconds, once), but neither waits on the other's photos meanwhile.
        let plan = self.optimise(width, height)?;
        if let Ok(mut plans) = self.plans.lock() {
            plans.insert((width, height), plan.clone());
        }
        Ok(plan)
    }

    /// The graph typed for `width × height` inputs, its output checked to be
    /// `[1, channels, height, width]`.
    fn typed(&self, width: u32, height: u32) -> Result<TypedModel, SegmentError> {
        let fed = format!("[1, 3, {height}, {width}]");
        let shape_error = |message: String| SegmentError::Shape {
            path: self.path.clone(),
            message,
        };
        let input_fact = f32::fact([1, 3, height as usize, width as usize]);
        let typed = self
            .graph
            .clone()
            .with_input_fact(0, input_fact.into())
            .and_then(|g| g.into_typed())
            .map_err(|e| {
                shape_error(format!(
                    "the model does not take a {fed} float image: {}",
                    one_line(e)
                ))
            })?;
        let expected = [1, self.channels, height as usize, width as usize];
        let out_shape = typed
            .output_fact(0)
            .ok()
            .and_then(|f| f.shape.as_concrete().map(|s| s.to_vec()));
        if out_shape.as_deref() != Some(&expected[..]) {
            let got = typed
                .output_fact(0)
                .map(|f| format!("{:?}", f.shape))
                .unwrap_or_else(|_| "unknown".into());
            return Err(shape_error(format!(
                "for a {fed} input the model's output is [{got}]; segmentation reads {expected:?} \
                 (one channel per class, the input's size)"
            )));
        }
        Ok(typed)
    }

    fn optimise(&self, width: u32, height: u32) -> Result<Plan, SegmentError> {
        self.typed(width, height)?
            .into_optimized()
            .and_then(|m| m.into_runnable())
            .map_err(|e| SegmentError::Model {
                path: self.path.clone(),
                message: one_line(e),
            })
    }

    /// Runs the model on one `width × height` input (`data` planar: 3 planes of
    /// `width · height`, NCHW); returns its `channels` output planes, raw (before any
    /// activation). `photo` names the photo in an error.
    pub fn run(
        &self,
        data: Vec<f32>,
        width: u32,
        height: u32,
        photo: &Path,
    ) -> Result<Vec<f32>, SegmentError> {
        let plan = self.plan(width, height)?;
        let run_error = |e: TractError| SegmentError::Run {
            path: photo.to_path_buf(),
            message: one_line(e),
        };
        let shape = [1, 3, height as usize, width as usize];
        let input = tract_ndarray::Array4::from_shape_vec(shape, data)
            .map_err(|e| SegmentError::Run {
                path: photo.to_path_buf(),
                message: e.to_string(),
            })?
            .into_tensor();
        let outputs = plan.run(tvec!(input.into())).map_err(run_error)?;
        let first = outputs.first().ok_or_else(|| SegmentError::Run {
            path: photo.to_path_buf(),
            message: "the model returned no output".into(),
        })?;
        let values = first
            .try_as_plain_ram()
            .and_then(|v| v.as_slice::<f32>().map(<[f32]>::to_vec))
            .map_err(run_error)?;
        let expected = self.channels * width as usize * height as usize;
        if values.len() != expected {
            return Err(SegmentError::Shape {
                path: self.path.clone(),
                message: format!(
                    "the model returned {} values for a {width}×{height} input, not {expected}",
                    values.len()
                ),
            });
        }
        Ok(values)
    }
}
