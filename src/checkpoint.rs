//! Checkpoint brains: the course's ch2.1 PPO actor from a PyTorch `state_dict`
//! (`.pt`/`.pth`), the same tensors as `.safetensors`, or its ONNX export (`.onnx`).
//!
//! The actor is `Linear(5, h) → tanh → Linear(h, h) → tanh → Linear(h, 1)` (keys
//! `actor_mean.{0,2,4}.{weight,bias}`; critic and `actor_logstd` entries are ignored). The
//! hidden width `h` is inferred from `actor_mean.0.weight`, as the chapter does. The brain
//! acts with the deterministic mean (no sampling); the plant clips to [-1, 1].
//!
//! Formats are read with well-kept crates: candle-core's PyTorch reader (a restricted
//! unpickler that only rebuilds tensors — like `torch.load(weights_only=True)`, it never
//! executes code from the file) and its safetensors support; tract-onnx for ONNX
//! (contract v1: input `float32[1,5]`, output `float32[1,1]`).

use crate::plant::{Action, Observation, ACT_DIM, OBS_DIM};
use crate::policy::{Policy, Scripted};
use candle_core::{DType, Device, Tensor};
use std::collections::HashMap;
use std::path::{Path, PathBuf};
use tract_onnx::prelude::*;

/// The actor's six tensors, in order.
pub const ACTOR_KEYS: [&str; 6] = [
    "actor_mean.0.weight",
    "actor_mean.0.bias",
    "actor_mean.2.weight",
    "actor_mean.2.bias",
    "actor_mean.4.weight",
    "actor_mean.4.bias",
];

/// Why a brain could not be loaded. Every message is one line and names the file.
#[derive(Debug, thiserror::Error)]
pub enum PolicyError {
    /// The path does not exist (no silent fallback: the user asked for that file).
    #[error("policy file not found: {0}")]
    NotFound(PathBuf),
    /// The path is not a regular file.
    #[error("policy path is not a file: {0}")]
    NotAFile(PathBuf),
    /// Not a checkpoint of any supported format.
    #[error("{path}: not a {format} checkpoint ({detail})")]
    Format {
        /// The file.
        path: PathBuf,
        /// The format it was read as.
        format: &'static str,
        /// The reader's complaint.
        detail: String,
    },
    /// An extension ratelab cannot read.
    #[error(
        "{0}: unsupported policy file type (expected scripted, .pt, .pth, .safetensors or .onnx)"
    )]
    UnknownType(PathBuf),
    /// Actor tensors missing from the checkpoint.
    #[error("{path}: missing actor tensors: {}", keys.join(", "))]
    MissingKeys {
        /// The file.
        path: PathBuf,
        /// The missing keys.
        keys: Vec<String>,
    },
    /// A tensor of the wrong shape.
    #[error("{path}: tensor '{tensor}' has shape {found:?}, expected {expected:?}")]
    Shape {
        /// The file.
        path: PathBuf,
        /// The tensor.
        tensor: String,
        /// What the architecture needs.
        expected: Vec<usize>,
        /// What the file holds.
        found: Vec<usize>,
    },
    /// The first layer reads an observation of another width.
    #[error("{path}: the actor reads {found}-wide observations; the cartpole publishes {expected}", expected = OBS_DIM)]
    ObsWidth {
        /// The file.
        path: PathBuf,
        /// The width found.
        found: usize,
    },
    /// A tensor whose dtype cannot become float32 (integers, booleans).
    #[error("{path}: tensor '{tensor}' is {dtype:?}, which cannot be converted to float32")]
    DType {
        /// The file.
        path: PathBuf,
        /// The tensor.
        tensor: String,
        /// Its dtype.
        dtype: DType,
    },
    /// An ONNX model outside contract v1.
    #[error("{path}: ONNX model does not fit contract v1 (input float32[1,5], output float32[1,1]): {detail}")]
    OnnxContract {
        /// The file.
        path: PathBuf,
        /// What does not fit.
        detail: String,
    },
    /// A tensor operation failed (should not happen after validation).
    #[error("{path}: {detail}")]
    Tensor {
        /// The file.
        path: PathBuf,
        /// The error.
        detail: String,
    },
}

/// Load the brain named by `spec`: `scripted`, or a checkpoint path (by extension:
/// `.pt`/`.pth` PyTorch zip, `.safetensors`, `.onnx`).
///
/// # Errors
/// [`PolicyError`]: the file is missing, unreadable, of no supported format, or does not
/// hold the ch2.1 actor (missing keys, shapes, observation width, dtypes, ONNX contract).
pub fn load_policy(spec: &str) -> Result<Box<dyn Policy>, PolicyError> {
    if spec == "scripted" {
        return Ok(Box::new(Scripted));
    }
    let path = Path::new(spec);
    if !path.exists() {
        return Err(PolicyError::NotFound(path.to_path_buf()));
    }
    if !path.is_file() {
        return Err(PolicyError::NotAFile(path.to_path_buf()));
    }
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase);
    match ext.as_deref() {
        Some("pt" | "pth") => Ok(Box::new(MlpPolicy::from_tensors(
            path,
            read_torch(path)?,
            "ch2.1 PPO checkpoint",
        )?)),
        Some("safetensors") => Ok(Box::new(MlpPolicy::from_tensors(
            path,
            read_safetensors(path)?,
            "ch2.1 PPO safetensors",
        )?)),
        Some("onnx") => Ok(Box::new(OnnxPolicy::load(path)?)),
        _ => Err(PolicyError::UnknownType(path.to_path_buf())),
    }
}

fn format_err(path: &Path, format: &'static str, detail: impl std::fmt::Display) -> PolicyError {
    let detail = detail.to_string();
    let detail = detail.lines().next().unwrap_or("unreadable").to_string();
    PolicyError::Format {
        path: path.to_path_buf(),
        format,
        detail,
    }
}

/// Run a third-party reader, turning a panic inside it into an error (a malformed file
/// must never take the process down).
fn guarded<T>(f: impl FnOnce() -> T) -> Result<T, String> {
    std::panic::catch_unwind(std::panic::AssertUnwindSafe(f)).map_err(|p| {
        p.downcast_ref::<&str>()
            .map(|s| s.to_string())
            .or_else(|| p.downcast_ref::<String>().cloned())
            .unwrap_or_else(|| "reader panicked".into())
    })
}

/// Every tensor of a PyTorch `state_dict` saved with `torch.save` (zip format).
///
/// # Errors
/// [`PolicyError::Format`] when the file is not such an archive.
pub fn read_torch(path: &Path) -> Result<HashMap<String, Tensor>, PolicyError> {
    let tensors = guarded(|| candle_core::pickle::read_all(path))
        .map_err(|p| format_err(path, "PyTorch", p))?
        .map_err(|e| format_err(path, "PyTorch", e))?;
    Ok(tensors.into_iter().collect())
}

/// Every tensor of a `.safetensors` file.
///
/// # Errors
/// [`PolicyError::Format`] when the file is not safetensors.
pub fn read_safetensors(path: &Path) -> Result<HashMap<String, Tensor>, PolicyError> {
    guarded(|| candle_core::safetensors::load(path, &Device::Cpu))
        .map_err(|p| format_err(path, "safetensors", p))?
        .map_err(|e| format_err(path, "safetensors", e))
}

/// One dense layer, `y = W x + b`, float32, `W` row-major `[out][in]`.
struct Dense {
    w: Vec<f32>,
    b: Vec<f32>,
    n_in: usize,
}

impl Dense {
    fn apply(&self, x: &[f32], y: &mut Vec<f32>) {
        y.clear();
        y.extend(
            self.b
                .iter()
                .zip(self.w.chunks_exact(self.n_in))
                .map(|(b, row)| b + row.iter().zip(x).map(|(w, x)| w * x).sum::<f32>()),
        );
    }
}

/// The ch2.1 actor MLP: tensors read and validated with candle, evaluated on the CPU.
///
/// The forward pass runs directly on the loaded weights rather than as candle ops: at
/// this size candle's per-op dispatch dominates (measured 128 µs per call for the 64-wide
/// net, against a budget of 20 µs for a 1 kHz policy; see BENCHMARKS.md).
pub struct MlpPolicy {
    layers: Vec<Dense>,
    hidden: usize,
    label: String,
    scratch: (Vec<f32>, Vec<f32>),
}

impl MlpPolicy {
    /// Validate the actor tensors and build the network.
    ///
    /// # Errors
    /// [`PolicyError`] for missing keys, shapes, observation width or dtypes.
    pub fn from_tensors(
        path: &Path,
        tensors: HashMap<String, Tensor>,
        kind: &str,
    ) -> Result<Self, PolicyError> {
        let missing: Vec<String> = ACTOR_KEYS
            .iter()
            .filter(|k| !tensors.contains_key(**k))
            .map(|k| k.to_string())
            .collect();
        if !missing.is_empty() {
            return Err(PolicyError::MissingKeys {
                path: path.to_path_buf(),
                keys: missing,
            });
        }
        let get = |key: &str| -> Result<Tensor, PolicyError> {
            let t = &tensors[key];
            match t.dtype() {
                DType::F32 => Ok(t.clone()),
                DType::F16 | DType::BF16 | DType::F64 => {
                    t.to_dtype(DType::F32).map_err(|e| PolicyError::Tensor {
                        path: path.to_path_buf(),
                        detail: e.to_string(),
                    })
                }
                dtype => Err(PolicyError::DType {
                    path: path.to_path_buf(),
                    tensor: key.into(),
                    dtype,
                }),
            }
        };
        let w0 = get(ACTOR_KEYS[0])?;
        let dims0 = w0.dims().to_vec();
        if dims0.len() != 2 {
            return Err(PolicyError::Shape {
                path: path.to_path_buf(),
                tensor: ACTOR_KEYS[0].into(),
                expected: vec![64, OBS_DIM],
                found: dims0,
            });
        }
        let (hidden, obs_width) = (dims0[0], dims0[1]);
        if obs_width != OBS_DIM {
            return Err(PolicyError::ObsWidth {
                path: path.to_path_buf(),
                found: obs_width,
            });
        }
        let expected: [(usize, Vec<usize>); 6] = [
            (0, vec![hidden, OBS_DIM]),
            (1, vec![hidden]),
            (2, vec![hidden, hidden]),
            (3, vec![hidden]),
            (4, vec![ACT_DIM, hidden]),
            (5, vec![ACT_DIM]),
        ];
        let mut checked = Vec::with_capacity(6);
        for (i, shape) in expected {
            let t = get(ACTOR_KEYS[i])?;
            if t.dims() != shape.as_slice() {
                return Err(PolicyError::Shape {
                    path: path.to_path_buf(),
                    tensor: ACTOR_KEYS[i].into(),
                    expected: shape,
                    found: t.dims().to_vec(),
                });
            }
            checked.push(t);
        }
        let tensor_err = |e: candle_core::Error| PolicyError::Tensor {
            path: path.to_path_buf(),
            detail: e.to_string(),
        };
        let mut layers = Vec::with_capacity(3);
        for pair in checked.chunks(2) {
            let w: Vec<f32> = pair[0]
                .flatten_all()
                .and_then(|t| t.to_vec1())
                .map_err(tensor_err)?;
            let b: Vec<f32> = pair[1].to_vec1().map_err(tensor_err)?;
            layers.push(Dense {
                n_in: pair[0].dims()[1],
                w,
                b,
            });
        }
        Ok(Self {
            layers,
            hidden,
            label: format!("{kind} ({}, hidden {hidden})", path.display()),
            scratch: (Vec::with_capacity(hidden), Vec::with_capacity(hidden)),
        })
    }

    /// The hidden width inferred from the checkpoint.
    pub fn hidden(&self) -> usize {
        self.hidden
    }

    fn forward(&mut self, obs: &Observation) -> f32 {
        let (x, y) = &mut self.scratch;
        x.clear();
        x.extend_from_slice(obs);
        let last = self.layers.len() - 1;
        for (i, layer) in self.layers.iter().enumerate() {
            layer.apply(x, y);
            if i < last {
                y.iter_mut().for_each(|v| *v = v.tanh());
            }
            std::mem::swap(x, y);
        }
        x[0]
    }
}

impl Policy for MlpPolicy {
    fn act(&mut self, obs: &Observation) -> Action {
        [self.forward(obs)]
    }

    fn label(&self) -> String {
        self.label.clone()
    }
}

/// An ONNX actor (contract v1), run by tract.
pub struct OnnxPolicy {
    plan: Arc<TypedSimplePlan>,
    label: String,
}

fn describe_fact(f: &TypedFact) -> String {
    format!(
        "{:?}{:?}",
        f.datum_type,
        f.shape
            .to_tvec()
            .iter()
            .map(|d| d.to_string())
            .collect::<Vec<_>>()
    )
}

/// Does `fact` fit `float32[1, width]` (a symbolic batch dimension is accepted)?
fn fits(fact: &TypedFact, width: usize) -> bool {
    let dims = fact.shape.to_tvec();
    fact.datum_type == f32::datum_type()
        && dims.len() == 2
        && (dims[0] == TDim::Val(1) || dims[0].to_i64().is_err())
        && dims[1] == TDim::Val(width as i64)
}

impl OnnxPolicy {
    /// Load and check an ONNX model against contract v1.
    ///
    /// # Errors
    /// [`PolicyError::Format`] when the file is not ONNX, [`PolicyError::OnnxContract`]
    /// when its input or output does not fit.
    pub fn load(path: &Path) -> Result<Self, PolicyError> {
        let contract = |detail: String| PolicyError::OnnxContract {
            path: path.to_path_buf(),
            detail,
        };
        let model = guarded(|| tract_onnx::onnx().model_for_path(path))
            .map_err(|p| format_err(path, "ONNX", p))?
            .map_err(|e| format_err(path, "ONNX", e))?;
        let (n_in, n_out) = (model.inputs.len(), model.outputs.len());
        if n_in != 1 || n_out != 1 {
            return Err(contract(format!(
                "{n_in} inputs and {n_out} outputs, expected 1 and 1"
            )));
        }
        let typed = model
            .into_typed()
            .map_err(|e| format_err(path, "ONNX", e))?;
        let input = typed
            .input_fact(0)
            .map_err(|e| contract(e.to_string()))?
            .clone();
        if !fits(&input, OBS_DIM) {
            return Err(contract(format!("input is {}", describe_fact(&input))));
        }
        let output = typed
            .output_fact(0)
            .map_err(|e| contract(e.to_string()))?
            .clone();
        if !fits(&output, ACT_DIM) {
            return Err(contract(format!("output is {}", describe_fact(&output))));
        }
        // Pin the batch to 1, then optimize for that shape.
        let pinned = tract_onnx::onnx()
            .model_for_path(path)
            .and_then(|m| {
                m.with_input_fact(
                    0,
                    InferenceFact::dt_shape(f32::datum_type(), tvec!(1, OBS_DIM)),
                )
            })
            .and_then(|m| m.into_optimized())
            .and_then(TypedSimplePlan::new)
            .map_err(|e| contract(e.to_string()))?;
        Ok(Self {
            plan: pinned,
            label: format!("ONNX policy ({})", path.display()),
        })
    }

    fn forward(&self, obs: &Observation) -> TractResult<f32> {
        let input = Tensor1x5(obs).into_tract()?;
        let out = self.plan.run(tvec!(input.into()))?;
        let view = out[0].to_plain_array_view::<f32>()?;
        view.iter()
            .next()
            .copied()
            .ok_or_else(|| anyhow::anyhow!("empty output"))
    }
}

struct Tensor1x5<'a>(&'a Observation);

impl Tensor1x5<'_> {
    fn into_tract(self) -> TractResult<tract_onnx::prelude::Tensor> {
        tract_onnx::prelude::Tensor::from_shape(&[1, OBS_DIM], self.0)
    }
}

impl Policy for OnnxPolicy {
    fn act(&mut self, obs: &Observation) -> Action {
        [self.forward(obs).unwrap_or(f32::NAN)]
    }

    fn label(&self) -> String {
        self.label.clone()
    }
}
