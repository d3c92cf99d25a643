//! Synthetic mesh sets with known parameters. Filled in by the synthetic-data work.
