//! Checkpoint brains: the course's ch2.1 PPO actor from a PyTorch `state_dict`
//! (`.pt`/`.pth`), the same tensors as `.safetensors`, or its ONNX export (`.onnx`).
//!
//! The actor is `Linear(5, h) → tanh → Linear(h, h) → tanh → Linear(h, 1)` (keys
//! `actor_mean.{0,2,4}.{weight,bias}`; critic and `actor_logstd` entries are ignored). The
//! hidden width `h` is inferred from `actor_mean.0.weight`, as the chapter does. The brain
//! acts with the deterministic mean (no sampling); the plant clips to [-1, 1].
//!
//! Every file is untrusted input: loading any file is bounded in memory (well under
//! 256 MiB resident), in time (well under 5 s) and in recursion, and any refusal is one
//! line naming the file. Files are read once, from regular files only, with a size cap per
//! format ([`MAX_FILE_BYTES`], [`MAX_ONNX_BYTES`]); third-party readers run under
//! [`guarded`], which turns their panics into errors without printing them.
//!
//! - PyTorch: [`torch`] checks the zip archive (CRCs, local headers), pre-scans the pickle
//!   program with limits and an allow-list of globals (as `torch.load(weights_only=True)`),
//!   then lets candle-core's unpickler build the object tree, and checks every tensor's
//!   shape against its storage before anything is allocated. Its docs say why.
//! - safetensors: the safetensors crate (built for untrusted input: it checks every
//!   tensor's extent against the buffer) over the capped buffer.
//! - ONNX (contract v1: input `float32[1,5]`, output `float32[1,1]`), run by tract-onnx:
//!   before tract builds anything, the decoded model is checked: operator set in
//!   [`ONNX_OPSETS`], no external data, no string tensors, every declared tensor within
//!   [`MAX_ONNX_ELEMENTS`], at most [`MAX_ONNX_ITEMS`] nodes and edges; after typing
//!   with the batch pinned to 1, every intermediate tensor is checked the same way.

use crate::plant::{Action, Observation, ACT_DIM, OBS_DIM};
use crate::policy::{Policy, Scripted};
use candle_core::{DType, Device, Tensor};
use ratelab_core::input::{read_regular_file, InputError};
use std::collections::HashMap;
use std::ops::RangeInclusive;
use std::path::{Path, PathBuf};
use tract_onnx::prelude::*;

pub mod export;
pub mod torch;

pub use torch::MAX_FILE_BYTES;

/// The largest ONNX file read, bytes. Decoding protobuf can take a few hundred times a
/// message's encoded size (an empty node is 2 bytes on disk and a few hundred in memory),
/// so the cap is tighter than for the other formats; the course's actor is 19 KB, and
/// 512 KiB hold a contract-v1 actor about 350 wide.
pub const MAX_ONNX_BYTES: u64 = 512 << 10;

/// The ONNX operator sets (default domain) accepted: tested from 9 (the oldest tract
/// supports) to 20 (the course's exporter). Others are refused rather than guessed at.
pub const ONNX_OPSETS: RangeInclusive<i64> = 9..=20;

/// The most nodes, tensors, node inputs and outputs, and attributes of an ONNX model, all
/// graphs together (the course's actor has a few dozen).
pub const MAX_ONNX_ITEMS: u64 = 10_000;

/// The most elements of any one tensor of an ONNX model (declared or inferred), and
/// twice this over all its declared tensors together.
pub const MAX_ONNX_ELEMENTS: u64 = 4 << 20;

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
    /// The file cannot be read (permissions, size cap, I/O): the reason, naming the file.
    #[error("cannot read policy file {0}")]
    Unreadable(InputError),
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
        "{0}: unsupported policy file type (expected scripted, .py[:FUNCTION], .pt, .pth, .safetensors or .onnx)"
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
    /// An actor tensor held in a storage type ratelab cannot read (e.g. `torch.BoolStorage`).
    #[error(
        "{path}: tensor '{tensor}' is stored as {storage}, which cannot be converted to float32"
    )]
    Storage {
        /// The file.
        path: PathBuf,
        /// The tensor.
        tensor: String,
        /// The storage type.
        storage: String,
    },
    /// The actor's hidden layers have width 0 (nothing to compute with).
    #[error("{path}: the actor's hidden width is 0 (tensor '{tensor}' has shape {found:?})")]
    ZeroWidth {
        /// The file.
        path: PathBuf,
        /// The tensor.
        tensor: String,
        /// Its shape.
        found: Vec<usize>,
    },
    /// A Python brain (`FILE.py[:FUNCTION]`) that cannot be loaded: the one-line reason
    /// (the Python layer's, or [`crate::graph::interpreter::NOT_INSTALLED`]).
    #[error("{0}")]
    Python(String),
    /// A tensor operation failed (should not happen after validation).
    #[error("{path}: {detail}")]
    Tensor {
        /// The file.
        path: PathBuf,
        /// The error.
        detail: String,
    },
}

/// Load the brain named by `spec`: `scripted`, a Python function (`FILE.py[:FUNCTION]`,
/// `ratelab::python::brain`), or a checkpoint path (by extension: `.pt`/`.pth` PyTorch zip,
/// `.safetensors`, `.onnx`).
///
/// # Errors
/// [`PolicyError`]: the file is missing, unreadable, not a regular file, too large, of no
/// supported format, hostile (see the module docs), or does not hold the ch2.1 actor
/// (missing keys, shapes, width 0, observation width, dtypes, ONNX contract).
pub fn load_policy(spec: &str) -> Result<Box<dyn Policy>, PolicyError> {
    if spec == "scripted" {
        return Ok(Box::new(Scripted));
    }
    if let Some((script, function)) = crate::graph::interpreter::parse_spec(spec) {
        let python = crate::graph::interpreter::installed().map_err(PolicyError::Python)?;
        return python.brain(script, function).map_err(|e| match e.missing {
            true => PolicyError::NotFound(PathBuf::from(script)),
            false => PolicyError::Python(e.line),
        });
    }
    let brain = load_checkpoint(spec)?;
    Ok(match caption(Path::new(spec)) {
        Some(caption) => Box::new(Captioned {
            label: format!("{} — {caption}", brain.label()),
            inner: brain,
        }),
        None => brain,
    })
}

/// The largest caption sidecar read, bytes.
pub const MAX_CAPTION_BYTES: u64 = 1024;

/// What a checkpoint is, in one line, when known: the first line of a sidecar
/// `<checkpoint>.caption` beside it, else the caption of a known checkpoint by the file's
/// SHA-256 (`src/runtime/assets/captions.toml`: the course's fixtures). `None` when neither says.
/// Read through [`ratelab_core::input`]'s rule, bounded; a sidecar that cannot be read is ignored.
pub fn caption(path: &Path) -> Option<String> {
    let mut sidecar = path.as_os_str().to_owned();
    sidecar.push(".caption");
    if let Ok(bytes) =
        ratelab_core::input::read_regular_file(Path::new(&sidecar), MAX_CAPTION_BYTES)
    {
        let text = String::from_utf8_lossy(&bytes);
        let line = text.lines().next().unwrap_or("").trim();
        if !line.is_empty() {
            // The label of the brain in the summary, the lab and a recording.
            return Some(
                ratelab_core::text::printable(line)
                    .chars()
                    .take(200)
                    .collect(),
            );
        }
    }
    use sha2::Digest;
    let bytes = ratelab_core::input::read_regular_file(path, MAX_FILE_BYTES).ok()?;
    let digest = sha2::Sha256::digest(&bytes);
    let hex: String = digest.iter().map(|b| format!("{b:02x}")).collect();
    let known: toml::Table = toml::from_str(include_str!("assets/captions.toml")).ok()?;
    known.get(&hex)?.as_str().map(str::to_string)
}

/// A brain with a caption in its label; acts as the brain it wraps.
struct Captioned {
    inner: Box<dyn Policy>,
    label: String,
}

impl Policy for Captioned {
    fn act(&mut self, obs: &crate::plant::Observation) -> crate::plant::Action {
        self.inner.act(obs)
    }
    fn label(&self) -> String {
        self.label.clone()
    }
    fn duplicate(&self) -> Option<Box<dyn Policy>> {
        Some(Box::new(Captioned {
            inner: self.inner.duplicate()?,
            label: self.label.clone(),
        }))
    }
}

/// Load a checkpoint brain (no caption).
/// A path's extension, lower-cased: how a checkpoint's format is told.
fn extension(path: &Path) -> Option<String> {
    path.extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase)
}

/// Why `path`, of no format the caller reads, is refused: missing, not a regular file, or
/// of an unsupported type (a missing file is named as missing, whatever its extension).
fn not_a_checkpoint(path: &Path) -> PolicyError {
    match std::fs::metadata(path) {
        Err(e) => input_err(path, ratelab_core::input::io_error(path, &e)),
        Ok(m) if !m.is_file() => PolicyError::NotAFile(path.to_path_buf()),
        Ok(_) => PolicyError::UnknownType(path.to_path_buf()),
    }
}

fn load_checkpoint(spec: &str) -> Result<Box<dyn Policy>, PolicyError> {
    let path = Path::new(spec);
    match extension(path).as_deref() {
        Some("pt" | "pth") => {
            let bytes = read_input(path, MAX_FILE_BYTES)?;
            let read = guarded(|| torch::read(&bytes, Some(&ACTOR_KEYS[..])))
                .and_then(|r| r)
                .map_err(|e| format_err(path, "PyTorch", e))?;
            if let Some((tensor, storage)) = ACTOR_KEYS
                .iter()
                .find_map(|k| read.unsupported.get(*k).map(|s| (k.to_string(), s.clone())))
            {
                return Err(PolicyError::Storage {
                    path: path.to_path_buf(),
                    tensor,
                    storage,
                });
            }
            Ok(Box::new(MlpPolicy::from_tensors(
                path,
                read.tensors,
                "ch2.1 PPO checkpoint",
            )?))
        }
        Some("safetensors") => Ok(Box::new(MlpPolicy::from_tensors(
            path,
            read_safetensors(path)?,
            "ch2.1 PPO safetensors",
        )?)),
        Some("onnx") => Ok(Box::new(OnnxPolicy::load(path)?)),
        _ => Err(not_a_checkpoint(path)),
    }
}

fn input_err(path: &Path, e: InputError) -> PolicyError {
    match e {
        InputError::NotFound(_) => PolicyError::NotFound(path.to_path_buf()),
        InputError::NotRegular { .. } => PolicyError::NotAFile(path.to_path_buf()),
        other => PolicyError::Unreadable(other),
    }
}

fn read_input(path: &Path, max: u64) -> Result<Vec<u8>, PolicyError> {
    read_regular_file(path, max).map_err(|e| input_err(path, e))
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
/// must never take the process down). The panic's message is not printed
/// ([`crate::scheduler::catch_quietly`]).
///
/// # Errors
/// The panic's message (first line), prefixed with "the reader failed".
pub fn guarded<T>(f: impl FnOnce() -> T) -> Result<T, String> {
    let result = crate::scheduler::catch_quietly(f);
    result.map_err(|p| {
        let msg = crate::scheduler::panic_message(&*p);
        format!(
            "the reader failed: {}",
            msg.lines().next().unwrap_or("panic")
        )
    })
}

/// Every tensor of a PyTorch `state_dict` saved with `torch.save` (zip format), read as
/// untrusted input (see [`torch`]). All or nothing: a tensor whose storage type ratelab
/// cannot represent (e.g. `BoolStorage`) is refused, never left out without a word.
///
/// # Errors
/// [`PolicyError::Format`] when the file is not such an archive or is refused by the
/// checks; [`PolicyError::Storage`] naming the first such tensor (by key); the input errors
/// of [`load_policy`].
pub fn read_torch(path: &Path) -> Result<HashMap<String, Tensor>, PolicyError> {
    let bytes = read_input(path, MAX_FILE_BYTES)?;
    let read = guarded(|| torch::read(&bytes, None))
        .and_then(|r| r)
        .map_err(|e| format_err(path, "PyTorch", e))?;
    if let Some((tensor, storage)) = read.unsupported.iter().min_by_key(|(k, _)| k.as_str()) {
        return Err(PolicyError::Storage {
            path: path.to_path_buf(),
            tensor: tensor.clone(),
            storage: storage.clone(),
        });
    }
    Ok(read.tensors)
}

/// Every tensor of a `.safetensors` file (at most [`MAX_FILE_BYTES`]).
///
/// # Errors
/// [`PolicyError::Format`] when the file is not safetensors; the input errors of
/// [`load_policy`].
pub fn read_safetensors(path: &Path) -> Result<HashMap<String, Tensor>, PolicyError> {
    let bytes = read_input(path, MAX_FILE_BYTES)?;
    guarded(|| candle_core::safetensors::load_buffer(&bytes, &Device::Cpu))
        .map_err(|p| format_err(path, "safetensors", p))?
        .map_err(|e| format_err(path, "safetensors", e))
}

/// One dense layer, `y = W x + b`, float32, `W` row-major `[out][in]`.
#[derive(Clone)]
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
#[derive(Clone)]
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
        if hidden == 0 {
            return Err(PolicyError::ZeroWidth {
                path: path.to_path_buf(),
                tensor: ACTOR_KEYS[0].into(),
                found: dims0,
            });
        }
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

    /// The network keeps nothing between calls (any scratch is overwritten by each).
    fn duplicate(&self) -> Option<Box<dyn Policy>> {
        Some(Box::new(self.clone()))
    }
}

/// An ONNX actor (contract v1), run by tract.
#[derive(Clone)]
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
    /// Load and check an ONNX model against contract v1 (see the module docs for the
    /// checks made before tract builds anything).
    ///
    /// # Errors
    /// [`PolicyError::Format`] when the file is not ONNX or is refused by the checks,
    /// [`PolicyError::OnnxContract`] when its input or output does not fit; the input
    /// errors of [`load_policy`].
    pub fn load(path: &Path) -> Result<Self, PolicyError> {
        let contract = |detail: String| PolicyError::OnnxContract {
            path: path.to_path_buf(),
            detail,
        };
        let bytes = read_input(path, MAX_ONNX_BYTES)?;
        let proto = guarded(|| tract_onnx::onnx().proto_model_for_read(&mut &bytes[..]))
            .map_err(|p| format_err(path, "ONNX", p))?
            .map_err(|e| format_err(path, "ONNX", e))?;
        drop(bytes);
        check_onnx_proto(&proto).map_err(|e| format_err(path, "ONNX", e))?;
        let model = guarded(|| tract_onnx::onnx().model_for_proto_model(&proto))
            .map_err(|p| format_err(path, "ONNX", p))?
            .map_err(|e| format_err(path, "ONNX", e))?;
        let (n_in, n_out) = (model.inputs.len(), model.outputs.len());
        if n_in != 1 || n_out != 1 {
            return Err(contract(format!(
                "{n_in} inputs and {n_out} outputs, expected 1 and 1"
            )));
        }
        let typed = guarded(|| model.into_typed())
            .map_err(|p| format_err(path, "ONNX", p))?
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
        drop(typed);
        // Pin the batch to 1, check every intermediate tensor's size, then optimize.
        let pinned = guarded(|| {
            tract_onnx::onnx()
                .model_for_proto_model(&proto)
                .and_then(|m| {
                    m.with_input_fact(
                        0,
                        InferenceFact::dt_shape(f32::datum_type(), tvec!(1, OBS_DIM)),
                    )
                })
                .and_then(|m| m.into_typed())
        })
        .map_err(|p| format_err(path, "ONNX", p))?
        .map_err(|e| contract(e.to_string()))?;
        check_volumes(&pinned).map_err(|e| format_err(path, "ONNX", e))?;
        let plan = guarded(|| pinned.into_optimized().and_then(TypedSimplePlan::new))
            .map_err(|p| format_err(path, "ONNX", p))?
            .map_err(|e| contract(e.to_string()))?;
        Ok(Self {
            plan,
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

/// ONNX `TensorProto.data_type` of strings.
const ONNX_STRING: i32 = 8;

/// Check a decoded ONNX model before tract builds anything from it: operator set,
/// external data, string tensors, declared tensor sizes (in every graph and subgraph).
fn check_onnx_proto(proto: &tract_onnx::pb::ModelProto) -> Result<(), String> {
    let opset = proto
        .opset_import
        .iter()
        .find(|o| o.domain.is_empty() || o.domain == "ai.onnx")
        .map(|o| o.version)
        .ok_or("no operator set for the default domain")?;
    if !ONNX_OPSETS.contains(&opset) {
        return Err(format!(
            "operator set {opset} is outside the supported {}..={}",
            ONNX_OPSETS.start(),
            ONNX_OPSETS.end()
        ));
    }
    let graph = proto.graph.as_ref().ok_or("the model has no graph")?;
    let mut total = 0u64;
    let mut items = 0u64;
    check_graph(graph, &mut total, &mut items, 0)
}

fn check_graph(
    g: &tract_onnx::pb::GraphProto,
    total: &mut u64,
    items: &mut u64,
    depth: u32,
) -> Result<(), String> {
    if depth > 8 {
        return Err("subgraphs nested deeper than 8 levels".into());
    }
    // tract builds a node with facts for each of these: bound how many (a contract-v1
    // actor has a few dozen; measured: 260 000 empty nodes cost tract about 300 MiB).
    *items += (g.node.len()
        + g.initializer.len()
        + g.sparse_initializer.len()
        + g.input.len()
        + g.output.len()
        + g.value_info.len()
        + g.node
            .iter()
            .map(|n| n.input.len() + n.output.len() + n.attribute.len())
            .sum::<usize>()) as u64;
    if *items > MAX_ONNX_ITEMS {
        return Err(format!(
            "more than {MAX_ONNX_ITEMS} nodes, tensors, edges and attributes"
        ));
    }
    for t in &g.initializer {
        check_tensor(t, total)?;
    }
    for s in &g.sparse_initializer {
        for t in s.values.iter().chain(&s.indices) {
            check_tensor(t, total)?;
        }
    }
    for node in &g.node {
        for a in &node.attribute {
            for t in a.t.iter().chain(&a.tensors) {
                check_tensor(t, total)?;
            }
            for s in a.sparse_tensor.iter().chain(&a.sparse_tensors) {
                for t in s.values.iter().chain(&s.indices) {
                    check_tensor(t, total)?;
                }
            }
            for sub in a.g.iter().chain(&a.graphs) {
                check_graph(sub, total, items, depth + 1)?;
            }
        }
    }
    Ok(())
}

fn check_tensor(t: &tract_onnx::pb::TensorProto, total: &mut u64) -> Result<(), String> {
    if t.data_location == Some(1) || !t.external_data.is_empty() {
        return Err(format!(
            "tensor '{}' refers to external data (only self-contained models are loaded)",
            t.name
        ));
    }
    if t.data_type == ONNX_STRING {
        return Err(format!("tensor '{}' holds strings", t.name));
    }
    let n = t
        .dims
        .iter()
        .try_fold(1u64, |n, &d| u64::try_from(d).ok().and_then(|d| n.checked_mul(d)))
        .filter(|&n| n <= MAX_ONNX_ELEMENTS)
        .ok_or_else(|| {
            format!(
                "tensor '{}' declares shape {:?} (negative, or more than {MAX_ONNX_ELEMENTS} elements)",
                t.name, t.dims
            )
        })?;
    *total += n;
    if *total > 2 * MAX_ONNX_ELEMENTS {
        return Err(format!(
            "tensors declare more than {} elements in all",
            2 * MAX_ONNX_ELEMENTS
        ));
    }
    Ok(())
}

/// Every tensor the typed model computes must be concrete and within [`MAX_ONNX_ELEMENTS`].
fn check_volumes(model: &TypedModel) -> Result<(), String> {
    for node in model.nodes() {
        for out in &node.outputs {
            let volume = out
                .fact
                .shape
                .as_concrete()
                .and_then(|dims| dims.iter().try_fold(1u64, |n, &d| n.checked_mul(d as u64)));
            match volume {
                Some(v) if v <= MAX_ONNX_ELEMENTS => {}
                _ => {
                    return Err(format!(
                        "node '{}' computes a tensor of shape {:?} (more than {MAX_ONNX_ELEMENTS} elements, or not fixed)",
                        node.name, out.fact.shape
                    ))
                }
            }
        }
    }
    Ok(())
}

struct Tensor1x5<'a>(&'a Observation);

impl Tensor1x5<'_> {
    fn into_tract(self) -> TractResult<tract_onnx::prelude::Tensor> {
        tract_onnx::prelude::Tensor::from_shape(&[1, OBS_DIM], self.0)
    }
}

impl Policy for OnnxPolicy {
    /// An error or a panic inside tract gives a non-finite action, which the actuator
    /// holds its last good action against and counts (never a crashed policy node).
    fn act(&mut self, obs: &Observation) -> Action {
        [guarded(|| self.forward(obs))
            .ok()
            .and_then(Result::ok)
            .unwrap_or(f32::NAN)]
    }

    fn label(&self) -> String {
        self.label.clone()
    }

    /// The network keeps nothing between calls (any scratch is overwritten by each).
    fn duplicate(&self) -> Option<Box<dyn Policy>> {
        Some(Box::new(self.clone()))
    }
}
