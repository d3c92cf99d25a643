//! Tests of the model's internals: tied convolutions are adjoints, the decoder's dense layer is
//! W_μᵀ.

use super::*;
use crate::net::config::ConvKind;
use crate::numerics::rng::Rng;
use mesh_hierarchy::{HierarchyConfig, Pooler};

fn hierarchy(config: &ModelConfig) -> Hierarchy {
    let sphere = qem_simplify::shapes::icosphere(2);
    Hierarchy::build(&sphere, &config.hierarchy_config()).unwrap()
}

fn random(shape: &[usize], seed: u64) -> Tensor {
    let mut rng = Rng::new(seed);
    let n = shape.iter().product();
    Tensor::from_vec(rng.normals(n), shape, &Device::Cpu).unwrap()
}

fn dot(a: &Tensor, b: &Tensor) -> f64 {
    (a * b).unwrap().sum_all().unwrap().to_scalar().unwrap()
}

#[test]
fn tied_decoder_convolutions_are_the_adjoints_of_the_encoders() {
    for conv in [ConvKind::Spectral, ConvKind::Spatial] {
        let config = ModelConfig {
            structure: "CCPC".parse().unwrap(),
            conv,
            channels: 5,
            latent: 4,
            tie_decoder_convs: true,
            ..Default::default()
        };
        let h = hierarchy(&config);
        let model = MeshVae::with_dtype(&config, &h, &Device::Cpu, DType::F64, 1).unwrap();
        // No decoder convolution weights exist: only batch norm and the dense bias.
        assert!(model.trainable().keys().all(|n| !n.starts_with("dec.conv")));
        for (i, enc) in model.encoder_blocks().enumerate() {
            let dec = model.decoder_blocks().find(|d| d.spec.index == i).unwrap();
            let v = model.vertex_counts[enc.spec.level];
            let x = random(&[2, v, enc.spec.c_in], 10 + i as u64);
            let y = random(&[2, v, enc.spec.c_out], 20 + i as u64);
            let tied = model.tied_conv(dec).unwrap().unwrap();
            let forward = dot(&enc.linear(&x, None).unwrap(), &y);
            let adjoint = dot(&x, &dec.linear(&y, Some(&tied)).unwrap());
            assert!(
                (forward - adjoint).abs() < 1e-12 * forward.abs().max(1e-3),
                "{conv:?} conv {i}: {forward} vs {adjoint}"
            );
            // Not trivially: a plain (untransposed) product would not satisfy it.
            assert!(forward.abs() > 1e-6);
        }
        // The gradient of a decoder-only loss reaches the encoder's convolution weights.
        let z = random(&[2, 4], 3);
        let out = model.decode(&z, None, Mode::Train).unwrap();
        let grads = model.backward(&out.sum_all().unwrap()).unwrap();
        let name = if conv == ConvKind::Spectral {
            "enc.conv0.weight"
        } else {
            "enc.conv0.w_nb"
        };
        assert!(grads.get(model.trainable()[name].as_tensor()).is_some());
    }
}

#[test]
fn the_decoder_dense_layer_is_the_transposed_mu_head() {
    let config = ModelConfig {
        structure: "CPC".parse().unwrap(),
        latent: 6,
        ..Default::default()
    };
    let h = hierarchy(&config);
    let model = MeshVae::with_dtype(&config, &h, &Device::Cpu, DType::F64, 2).unwrap();
    model.trainable()["dec.fc.bias"]
        .set(&random(&[model.flat_width()], 5))
        .unwrap();
    let z = random(&[3, 6], 4);
    let got: Vec<Vec<f64>> = model.decoder_fc(&z, None).unwrap().to_vec2().unwrap();
    let w: Vec<Vec<f64>> = model.trainable()["enc.mu.weight"]
        .as_tensor()
        .to_vec2()
        .unwrap();
    let b: Vec<f64> = model.trainable()["dec.fc.bias"]
        .as_tensor()
        .to_vec1()
        .unwrap();
    let zs: Vec<Vec<f64>> = z.to_vec2().unwrap();
    for (row, zr) in got.iter().zip(&zs) {
        for (p, &value) in row.iter().enumerate() {
            let want = b[p] + (0..6).map(|j| zr[j] * w[p][j]).sum::<f64>();
            assert!((value - want).abs() < 1e-12);
        }
    }
    assert!(!model.trainable().contains_key("dec.fc.weight"));
}

#[test]
fn hierarchy_of_another_pooler_or_depth_is_refused() {
    let mean = ModelConfig::default();
    let h = hierarchy(&mean);
    let qem = ModelConfig {
        pool: Pooler::Qem,
        ..Default::default()
    };
    let err = MeshVae::new(&qem, &h, &Device::Cpu, 0)
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("pooler mean") && err.contains("pool is qem"),
        "{err}"
    );
    let deep = ModelConfig {
        structure: "CPCPC".parse().unwrap(),
        ..Default::default()
    };
    let err = MeshVae::new(&deep, &h, &Device::Cpu, 0)
        .unwrap_err()
        .to_string();
    assert!(err.contains("needs 2"), "{err}");
    let flat = Hierarchy::build(
        &qem_simplify::shapes::icosphere(1),
        &HierarchyConfig {
            levels: 0,
            ..Default::default()
        },
    )
    .unwrap();
    assert!(MeshVae::new(&mean, &flat, &Device::Cpu, 0).is_err());
    assert!(
        MeshVae::with_dtype(&mean, &h, &Device::Cpu, DType::U8, 0)
            .unwrap_err()
            .to_string()
            .contains("dtype")
    );
}
