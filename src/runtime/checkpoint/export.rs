//! `ratelab export`: a checkpoint's tensors as a NumPy `.npz` archive, so a learner's Python
//! node can run the same network with NumPy alone (`graphs/nodes/ppo_numpy.py`), no PyTorch.
//!
//! The checkpoint is read exactly as a brain is (untrusted input, the same bounds: see
//! [`super`]); every tensor is written as float32 under its `state_dict` key (a tensor whose
//! storage ratelab cannot represent, such as `BoolStorage`, refuses the export: nothing is
//! left out without a word) (`np.load(FILE)["actor_mean.0.weight"]` has PyTorch's shape, `[out, in]`).
//! The archive is NumPy's own format, written by the `ndarray-npy` crate (uncompressed, as
//! `numpy.savez`).

use super::{read_safetensors, read_torch, PolicyError};
use candle_core::{DType, Tensor};
use std::collections::HashMap;
use std::path::Path;

/// One tensor as exported: its `state_dict` key, shape and float32 values (row-major).
#[derive(Clone, Debug, PartialEq)]
pub struct Exported {
    /// The `state_dict` key, e.g. `actor_mean.0.weight`.
    pub name: String,
    /// Its shape, e.g. `[64, 5]`.
    pub shape: Vec<usize>,
    /// Its values, row-major, float32.
    pub values: Vec<f32>,
}

/// The tensors of the checkpoint at `path` (`.pt`/`.pth` or `.safetensors`), sorted by key.
///
/// # Errors
/// The checkpoint's load errors ([`PolicyError`]: missing, not a regular file, unreadable,
/// hostile, not of one of these formats); [`PolicyError::UnknownType`] for an ONNX file or
/// another extension (an ONNX graph has no `state_dict`); [`PolicyError::Tensor`] when a tensor cannot be read as
/// float32.
pub fn checkpoint_tensors(path: &Path) -> Result<Vec<Exported>, PolicyError> {
    let tensors: HashMap<String, Tensor> = match super::extension(path).as_deref() {
        Some("pt" | "pth") => read_torch(path)?,
        Some("safetensors") => read_safetensors(path)?,
        _ => return Err(super::not_a_checkpoint(path)),
    };
    let tensor_err = |name: &str, e: candle_core::Error| PolicyError::Tensor {
        path: path.to_path_buf(),
        detail: format!("tensor '{name}': {e}"),
    };
    let mut out: Vec<Exported> = tensors
        .into_iter()
        .map(|(name, t)| {
            let values = t
                .to_dtype(DType::F32)
                .and_then(|t| t.flatten_all())
                .and_then(|t| t.to_vec1::<f32>())
                .map_err(|e| tensor_err(&name, e))?;
            Ok(Exported {
                shape: t.dims().to_vec(),
                name,
                values,
            })
        })
        .collect::<Result<_, PolicyError>>()?;
    out.sort_by(|a, b| a.name.cmp(&b.name));
    Ok(out)
}

/// The longest tensor name [`to_npz`] writes as an archive member, bytes (a PyTorch key such
/// as `actor.0.weight` is tens).
pub const MAX_TENSOR_NAME_BYTES: usize = 255;

/// A tensor name (a checkpoint's key, untrusted) fit to name an archive member as it is:
/// letters, digits, `_`, `.` and `-`, not starting with `.`, at most
/// [`MAX_TENSOR_NAME_BYTES`]. A name such as `../../etc/x` would otherwise become a member
/// that an unzip writes outside its folder.
fn plain_member_name(name: &str) -> bool {
    !name.is_empty()
        && name.len() <= MAX_TENSOR_NAME_BYTES
        && !name.starts_with('.')
        && (name.bytes()).all(|b| b.is_ascii_alphanumeric() || b"_.-".contains(&b))
}

/// `tensors` as the bytes of an uncompressed `.npz` archive (NumPy's `savez`), one float32
/// array per tensor named by its key.
///
/// # Errors
/// A message when a tensor's name is not a plain member name ([`plain_member_name`]'s
/// rule, nothing written), a shape does not match its values (not for
/// [`checkpoint_tensors`]' output) or the archive cannot be written.
pub fn to_npz(tensors: &[Exported]) -> Result<Vec<u8>, String> {
    if let Some(t) = tensors.iter().find(|t| !plain_member_name(&t.name)) {
        let shown: String = t.name.chars().take(80).collect();
        return Err(format!(
            "tensor {shown:?}: a name of letters, digits, '_', '.' and '-' (not starting with '.', at most {MAX_TENSOR_NAME_BYTES} bytes) is needed to name it in an archive"
        ));
    }
    let mut npz = ndarray_npy::NpzWriter::new(std::io::Cursor::new(Vec::new()));
    for t in tensors {
        let array = ndarray::ArrayD::from_shape_vec(t.shape.clone(), t.values.clone())
            .map_err(|e| format!("tensor '{}': {e}", t.name))?;
        npz.add_array(t.name.as_str(), &array)
            .map_err(|e| format!("tensor '{}': {e}", t.name))?;
    }
    npz.finish()
        .map(std::io::Cursor::into_inner)
        .map_err(|e| e.to_string())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_npz_round_trips_names_shapes_and_values() {
        let tensors = vec![
            Exported {
                name: "a.weight".into(),
                shape: vec![2, 3],
                values: vec![1.0, -2.5, 3.0, 0.0, f32::MIN_POSITIVE, 6.0],
            },
            Exported {
                name: "a.bias".into(),
                shape: vec![2],
                values: vec![0.5, -0.5],
            },
        ];
        let bytes = to_npz(&tensors).unwrap();
        let mut npz = ndarray_npy::NpzReader::new(std::io::Cursor::new(bytes)).unwrap();
        let mut names = npz.names().unwrap();
        names.sort();
        assert_eq!(names, ["a.bias", "a.weight"]);
        let w: ndarray::ArrayD<f32> = npz.by_name("a.weight").unwrap();
        assert_eq!(w.shape(), [2, 3]);
        assert_eq!(w.iter().copied().collect::<Vec<_>>(), tensors[0].values);
        let bad = Exported {
            name: "bad".into(),
            shape: vec![4],
            values: vec![1.0],
        };
        assert!(to_npz(&[bad]).unwrap_err().starts_with("tensor 'bad'"));
    }

    /// A checkpoint's keys are untrusted: one that would name a member outside the folder
    /// an unzip writes to (or a hidden one, or one of control characters) is refused, with
    /// nothing written.
    #[test]
    fn a_tensor_name_that_is_not_a_plain_member_name_is_refused() {
        let named = |name: &str| Exported {
            name: name.into(),
            shape: vec![1],
            values: vec![1.0],
        };
        for bad in [
            "../../etc/evil",
            "/abs",
            "a/b",
            "a\\b",
            ".hidden",
            "",
            "a\nb",
            "é",
        ] {
            let e = to_npz(&[named("ok.weight"), named(bad)]).unwrap_err();
            assert!(
                e.contains("is needed to name it in an archive"),
                "{bad:?}: {e}"
            );
            assert!(!e.contains('\n'), "{e}");
        }
        let long = "a".repeat(MAX_TENSOR_NAME_BYTES + 1);
        assert!(to_npz(&[named(&long)]).is_err());
        for good in [
            "actor.0.weight",
            "model.layers.10.self_attn.q_proj-bias",
            "a",
        ] {
            assert!(to_npz(&[named(good)]).is_ok(), "{good}");
        }
    }
}
