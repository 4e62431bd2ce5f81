//! Checkpoint brains: the course's real ch2.1 PPO checkpoint and its ONNX export, through
//! the same graph; and every kind of bad input, each refused with a clear error.

use candle_core::{DType, Device, Tensor};
use ratelab::checkpoint::{load_policy, read_torch, PolicyError, ACTOR_KEYS};
use ratelab::plant::Observation;
use ratelab::{run, ClockKind, RunConfig, RunOptions};
use std::collections::HashMap;
use std::path::{Path, PathBuf};

/// `../shared/fixtures`, beside the checkout. A missing fixture fails the test (never skips).
pub(crate) fn fixture(name: &str) -> PathBuf {
    let p = Path::new(crate::REPO).join("../shared/fixtures").join(name);
    assert!(
        p.is_file(),
        "fixture missing: {} (CI puts ../shared beside the checkout)",
        p.display()
    );
    p
}

#[derive(serde::Deserialize)]
struct Reference {
    hidden_dim: usize,
    obs: Vec<Observation>,
    action: Vec<[f32; 1]>,
}

fn reference() -> Reference {
    serde_json::from_str(
        &std::fs::read_to_string(fixture("ppo_ch2.1_seed0.reference_actions.json")).unwrap(),
    )
    .unwrap()
}

fn assert_matches_reference(spec: &Path) {
    let reference = reference();
    assert_eq!(reference.obs.len(), 32);
    let mut brain = load_policy(spec.to_str().unwrap()).unwrap();
    for (obs, want) in reference.obs.iter().zip(&reference.action) {
        let got = brain.act(obs);
        assert!(
            (got[0] - want[0]).abs() <= 1e-5,
            "{}: obs {obs:?}: got {} want {}",
            spec.display(),
            got[0],
            want[0]
        );
    }
}

#[test]
fn pytorch_checkpoint_matches_reference_actions() {
    assert_matches_reference(&fixture("ppo_ch2.1_seed0.pt"));
    let label = load_policy(fixture("ppo_ch2.1_seed0.pt").to_str().unwrap())
        .unwrap()
        .label();
    assert!(
        label.contains("ppo_ch2.1_seed0.pt") && label.contains("hidden 64"),
        "{label}"
    );
    assert_eq!(reference().hidden_dim, 64);
}

#[test]
fn onnx_export_matches_reference_actions() {
    assert_matches_reference(&fixture("ppo_ch2.1_seed0.onnx"));
}

fn save_safetensors(dir: &Path, name: &str, tensors: &HashMap<String, Tensor>) -> PathBuf {
    let path = dir.join(name);
    candle_core::safetensors::save(tensors, &path).unwrap();
    path
}

fn real_tensors() -> HashMap<String, Tensor> {
    read_torch(&fixture("ppo_ch2.1_seed0.pt")).unwrap()
}

#[test]
fn safetensors_variant_matches_reference_actions() {
    let dir = tempfile::tempdir().unwrap();
    let path = save_safetensors(dir.path(), "ppo.safetensors", &real_tensors());
    assert_matches_reference(&path);
}

#[test]
fn checkpoint_tensors_have_the_course_layout() {
    let t = real_tensors();
    assert_eq!(t.len(), 13);
    assert_eq!(t["actor_mean.0.weight"].dims(), &[64, 5]);
    assert_eq!(t["actor_mean.4.weight"].dims(), &[1, 64]);
    assert!(t.contains_key("actor_logstd") && t.contains_key("critic.4.bias"));
}

fn virtual_50hz(policy: &Path) -> ratelab::metrics::Metrics {
    let brain = load_policy(policy.to_str().unwrap()).unwrap();
    let cfg = RunConfig {
        clock: ClockKind::Virtual,
        ..RunConfig::default()
    };
    run(&cfg, brain, RunOptions::new()).unwrap().metrics
}

#[test]
fn checkpoint_falls_at_the_courses_control_step_293() {
    // Measured in the course's own runtime: virtual clock, seed 0, all rates 50 Hz.
    for name in ["ppo_ch2.1_seed0.pt", "ppo_ch2.1_seed0.onnx"] {
        let m = virtual_50hz(&fixture(name));
        assert!(!m.balanced, "{name}");
        assert_eq!(m.steps, 293, "{name}");
        assert_eq!(m.fell_at_s, Some(5.84), "{name}");
        assert!(m.policy.contains(name), "{}", m.policy);
    }
}

fn expect_err(spec: &Path) -> PolicyError {
    match load_policy(spec.to_str().unwrap()) {
        Ok(b) => panic!("{} loaded as {}", spec.display(), b.label()),
        Err(e) => {
            assert_eq!(e.to_string().lines().count(), 1, "one line: {e}");
            e
        }
    }
}

#[test]
fn missing_file_is_named_not_replaced_by_scripted() {
    let e = expect_err(Path::new("/nonexistent/ppo.pt"));
    assert!(matches!(e, PolicyError::NotFound(_)));
    assert!(e.to_string().contains("/nonexistent/ppo.pt"));
}

#[test]
fn random_bytes_are_not_a_checkpoint() {
    let dir = tempfile::tempdir().unwrap();
    let bytes: Vec<u8> = (0..4096u32)
        .map(|i| (i.wrapping_mul(2654435761) >> 13) as u8)
        .collect();
    for name in ["noise.pt", "noise.safetensors", "noise.onnx"] {
        let p = dir.path().join(name);
        std::fs::write(&p, &bytes).unwrap();
        assert!(
            matches!(expect_err(&p), PolicyError::Format { .. }),
            "{name}"
        );
    }
}

#[test]
fn empty_file_is_not_a_checkpoint() {
    let dir = tempfile::tempdir().unwrap();
    for name in ["empty.pt", "empty.safetensors", "empty.onnx"] {
        let p = dir.path().join(name);
        std::fs::write(&p, b"").unwrap();
        assert!(
            matches!(expect_err(&p), PolicyError::Format { .. }),
            "{name}"
        );
    }
}

#[test]
fn truncated_zip_is_not_a_checkpoint() {
    let dir = tempfile::tempdir().unwrap();
    let full = std::fs::read(fixture("ppo_ch2.1_seed0.pt")).unwrap();
    let p = dir.path().join("truncated.pt");
    std::fs::write(&p, &full[..full.len() / 2]).unwrap();
    assert!(matches!(expect_err(&p), PolicyError::Format { .. }));
}

#[test]
fn unknown_extension_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("brain.h5");
    std::fs::write(&p, b"x").unwrap();
    assert!(matches!(expect_err(&p), PolicyError::UnknownType(_)));
}

#[test]
fn missing_keys_are_listed() {
    let dir = tempfile::tempdir().unwrap();
    let mut t = real_tensors();
    t.remove("actor_mean.4.bias");
    t.remove("actor_mean.2.weight");
    let e = expect_err(&save_safetensors(dir.path(), "missing.safetensors", &t));
    let text = e.to_string();
    assert!(matches!(e, PolicyError::MissingKeys { .. }));
    assert!(
        text.contains("actor_mean.4.bias") && text.contains("actor_mean.2.weight"),
        "{text}"
    );
}

#[test]
fn wrong_shape_names_tensor_expected_and_found() {
    let dir = tempfile::tempdir().unwrap();
    let mut t = real_tensors();
    t.insert(
        "actor_mean.2.weight".into(),
        Tensor::zeros((64, 32), DType::F32, &Device::Cpu).unwrap(),
    );
    let e = expect_err(&save_safetensors(dir.path(), "shape.safetensors", &t));
    let text = e.to_string();
    assert!(
        text.contains("actor_mean.2.weight")
            && text.contains("[64, 64]")
            && text.contains("[64, 32]"),
        "{text}"
    );
}

#[test]
fn other_observation_width_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let mut t = real_tensors();
    t.insert(
        "actor_mean.0.weight".into(),
        Tensor::zeros((64, 7), DType::F32, &Device::Cpu).unwrap(),
    );
    let e = expect_err(&save_safetensors(dir.path(), "wide.safetensors", &t));
    assert!(matches!(e, PolicyError::ObsWidth { found: 7, .. }), "{e}");
}

#[test]
fn integer_tensors_cannot_be_converted() {
    let dir = tempfile::tempdir().unwrap();
    let mut t = real_tensors();
    t.insert(
        "actor_mean.0.bias".into(),
        Tensor::zeros(64, DType::I64, &Device::Cpu).unwrap(),
    );
    let e = expect_err(&save_safetensors(dir.path(), "ints.safetensors", &t));
    assert!(matches!(e, PolicyError::DType { .. }), "{e}");
    assert!(e.to_string().contains("actor_mean.0.bias"));
}

#[test]
fn float64_and_f16_tensors_are_converted() {
    let dir = tempfile::tempdir().unwrap();
    let t: HashMap<String, Tensor> = real_tensors()
        .into_iter()
        .map(|(k, v)| (k, v.to_dtype(DType::F64).unwrap()))
        .collect();
    assert_matches_reference(&save_safetensors(dir.path(), "f64.safetensors", &t));
    let t: HashMap<String, Tensor> = real_tensors()
        .into_iter()
        .map(|(k, v)| (k, v.to_dtype(DType::F16).unwrap()))
        .collect();
    let p = save_safetensors(dir.path(), "f16.safetensors", &t);
    assert!(load_policy(p.to_str().unwrap()).is_ok());
}

#[test]
fn hidden_width_is_inferred_not_assumed() {
    let dir = tempfile::tempdir().unwrap();
    let h = 16;
    let mut t = HashMap::new();
    let dev = Device::Cpu;
    for (key, shape) in ACTOR_KEYS.iter().zip([
        vec![h, 5],
        vec![h],
        vec![h, h],
        vec![h],
        vec![1, h],
        vec![1],
    ]) {
        t.insert(
            key.to_string(),
            Tensor::ones(shape, DType::F32, &dev).unwrap(),
        );
    }
    let p = save_safetensors(dir.path(), "h16.safetensors", &t);
    let mut brain = load_policy(p.to_str().unwrap()).unwrap();
    assert!(brain.label().contains("hidden 16"));
    // All-ones weights: tanh(5·1 + 1) saturates to ~1, then tanh(16 + 1) ≈ 1, out = 16 + 1.
    let a = brain.act(&[1.0; 5]);
    assert!((a[0] - 17.0).abs() < 1e-3, "{a:?}");
}

pub(crate) mod onnx_contract {
    use super::*;
    use prost::Message;
    use tract_onnx::pb::{
        tensor_shape_proto::{dimension, Dimension},
        type_proto, GraphProto, ModelProto, NodeProto, OperatorSetIdProto, TensorProto,
        TensorShapeProto, TypeProto, ValueInfoProto,
    };

    /// A tensor's name, element type and fixed shape, as an ONNX graph declares its inputs
    /// and outputs (shared with the hostile-input tests).
    pub(crate) fn value_info(name: &str, elem_type: i32, dims: &[i64]) -> ValueInfoProto {
        ValueInfoProto {
            name: name.into(),
            r#type: Some(TypeProto {
                value: Some(type_proto::Value::TensorType(type_proto::Tensor {
                    elem_type,
                    shape: Some(TensorShapeProto {
                        dim: dims
                            .iter()
                            .map(|&d| Dimension {
                                value: Some(dimension::Value::DimValue(d)),
                                ..Default::default()
                            })
                            .collect(),
                    }),
                })),
                ..Default::default()
            }),
            ..Default::default()
        }
    }

    /// `action = obs @ W`: a one-MatMul ONNX model with the given widths.
    fn matmul_model(dir: &Path, name: &str, obs_width: i64, act_width: i64) -> PathBuf {
        let model = ModelProto {
            ir_version: 8,
            opset_import: vec![OperatorSetIdProto {
                domain: String::new(),
                version: 13,
            }],
            graph: Some(GraphProto {
                name: "g".into(),
                node: vec![NodeProto {
                    input: vec!["obs".into(), "W".into()],
                    output: vec!["action".into()],
                    op_type: "MatMul".into(),
                    name: "mm".into(),
                    ..Default::default()
                }],
                initializer: vec![TensorProto {
                    name: "W".into(),
                    dims: vec![obs_width, act_width],
                    data_type: 1,
                    float_data: vec![0.5; (obs_width * act_width) as usize],
                    ..Default::default()
                }],
                input: vec![value_info("obs", 1, &[1, obs_width])],
                output: vec![value_info("action", 1, &[1, act_width])],
                ..Default::default()
            }),
            ..Default::default()
        };
        let p = dir.join(name);
        std::fs::write(&p, model.encode_to_vec()).unwrap();
        p
    }

    #[test]
    fn a_fitting_model_runs() {
        let dir = tempfile::tempdir().unwrap();
        let mut brain =
            load_policy(matmul_model(dir.path(), "ok.onnx", 5, 1).to_str().unwrap()).unwrap();
        assert_eq!(brain.act(&[1.0, 2.0, 3.0, 4.0, 0.0]), [5.0]);
    }

    #[test]
    fn wrong_input_width_breaks_contract() {
        let dir = tempfile::tempdir().unwrap();
        let e = expect_err(&matmul_model(dir.path(), "in7.onnx", 7, 1));
        assert!(matches!(e, PolicyError::OnnxContract { .. }), "{e}");
        assert!(e.to_string().contains("input"), "{e}");
    }

    #[test]
    fn wrong_output_width_breaks_contract() {
        let dir = tempfile::tempdir().unwrap();
        let e = expect_err(&matmul_model(dir.path(), "out2.onnx", 5, 2));
        assert!(matches!(e, PolicyError::OnnxContract { .. }), "{e}");
        assert!(e.to_string().contains("output"), "{e}");
    }
}

#[test]
fn known_checkpoints_and_sidecars_give_the_brain_a_caption() {
    // The course's fixtures are known by their SHA-256.
    for name in ["ppo_ch2.1_seed0.pt", "ppo_ch2.1_seed0.onnx"] {
        let label = load_policy(fixture(name).to_str().unwrap())
            .unwrap()
            .label();
        assert!(
            label.ends_with("— ch2.1 PPO (200k steps): imperfect, falls at 5.84 s even at 50 Hz"),
            "{label}"
        );
    }
    // A sidecar beside a checkpoint names it (first line), before the table of known ones.
    let dir = tempfile::tempdir().unwrap();
    let copy = dir.path().join("mine.onnx");
    std::fs::copy(fixture("ppo_ch2.1_seed0.onnx"), &copy).unwrap();
    std::fs::write(
        dir.path().join("mine.onnx.caption"),
        "my own actor, 1M steps\nignored\n",
    )
    .unwrap();
    let label = load_policy(copy.to_str().unwrap()).unwrap().label();
    assert!(label.ends_with("— my own actor, 1M steps"), "{label}");
    // One byte more and it is not the fixture any more: no caption without a sidecar.
    let plain = dir.path().join("plain.pt");
    let mut bytes = std::fs::read(fixture("ppo_ch2.1_seed0.pt")).unwrap();
    bytes.push(0);
    std::fs::write(&plain, bytes).unwrap();
    assert!(ratelab::checkpoint::caption(&plain).is_none());
    assert_eq!(
        load_policy("scripted").unwrap().label(),
        "scripted balancer (built-in, checkpoint-free)"
    );
}
