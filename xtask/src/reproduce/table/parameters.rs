//! The "Parameters" section: the paper's parameter counts beside Tan et al.'s derived ones and
//! our formula, then the parameters of each of our runs.

use super::{aggregate, percent};
use crate::reproduce::Outcome;
use crate::reproduce::paper;
use crate::reproduce::params;
use crate::reproduce::plan::COLUMNS;
use crate::reproduce::stats::thousands;
use std::fmt::Write;

pub(super) fn parameters(md: &mut String, o: &Outcome) {
    let t = params::TAN_ARCHITECTURE;
    md.push_str(
        "## Parameters\n\nCounted without biases, as the paper counts. Ours: 2·V₂·9·128 (the μ \
         and σ heads on the coarse level's V₂ vertices; the decoder's dense layer is tied to the \
         μ head) + 6·(3·9)·9 (six Chebyshev matrices, K = 3).\n\n",
    );
    let _ = writeln!(
        md,
        "Tan et al. 2018 (Mesh VAE), derived: a fully connected VAE on the {}·V feature vector — \
         encoder {}·V → {} (tanh), μ and σ heads {} → {}, decoder {} → {} → {}·V with its own \
         weights: 2·{}V·{} + 3·{}·{} weights. The Mesh VAE paper's text was not at hand offline; \
         the hidden width {} is our assumption (`xtask/src/reproduce/params.rs`, \
         `TAN_ARCHITECTURE`), and no single width reproduces both of the paper's rows (the exact \
         widths would be {:.1} and {:.1}), so the paper's figures include terms that cannot be \
         recovered from the totals.\n",
        t.per_vertex,
        t.per_vertex,
        t.hidden,
        t.hidden,
        t.latent,
        t.latent,
        t.hidden,
        t.per_vertex,
        t.per_vertex,
        t.hidden,
        t.hidden,
        t.latent,
        t.hidden,
        t.width_for(paper::PARAMS[0].vertices, paper::PARAMS[0].tan),
        t.width_for(paper::PARAMS[1].vertices, paper::PARAMS[1].tan),
    );
    md.push_str(
        "| data set | vertices | V₂ | Tan 2018 (paper) | Tan 2018 (derived) | distance | ours \
         (paper) | formula | `meshvae::param_count` |\n|---|---:|---:|---:|---:|---:|---:|---:|\
         ---:|\n",
    );
    for row in paper::PARAMS {
        let derived = params::tan2018(row.vertices);
        let _ = writeln!(
            md,
            "| {} | {} | {} | {} | {} | {} | {} | {} | {} |",
            row.dataset,
            thousands(row.vertices),
            thousands(row.coarse),
            thousands(row.tan),
            thousands(derived),
            percent(params::distance_percent(derived, row.tan)),
            thousands(row.ours),
            thousands(params::ours_formula(row.coarse)),
            thousands(params::ours_meshvae(row.vertices, row.coarse).without_biases),
        );
    }
    md.push_str(
        "\nOur runs (parameters without biases; with biases in brackets):\n\n| data set | \
         network | levels (vertices) | parameters | Tan 2018 (derived) |\n|---|---|---|---:|---:|\n",
    );
    for set in &o.sets {
        let name = set.dataset.name;
        for column in COLUMNS {
            let Some(a) = aggregate(&o.results, name, column.id) else {
                continue;
            };
            let levels: Vec<String> = a.levels.iter().map(|&v| thousands(v)).collect();
            let _ = writeln!(
                md,
                "| {name} | {} | {} | {} ({}) | {} |",
                column.label,
                levels.join(" → "),
                thousands(a.params_without_biases),
                thousands(a.params),
                thousands(params::tan2018(set.set.vertex_count())),
            );
        }
    }
    md.push('\n');
}
