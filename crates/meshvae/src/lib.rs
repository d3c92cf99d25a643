//! # meshvae: the mesh variational autoencoder
//!
//! Not built yet (issue "meshvae: the VAE"). In: a `mesh_io::MeshSet`. Out: a trained model
//! folder, evaluations and applications (generation, interpolation, embedding).
