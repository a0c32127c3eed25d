//! The SINDy model built symbolically: ẋᵢ = Σₖ Ξₖᵢ θₖ(x, u), or ẋᵢ = x_j for kinematic rows.

use crate::model::{Row, SindySpec};
use crate::symbolic::{Graph, Id};

pub fn dynamics(g: &mut Graph, vars: &[Id], spec: &SindySpec) -> Vec<Id> {
    let theta: Vec<Id> = spec.library.iter().map(|t| t.build(g, vars)).collect();
    spec.rows
        .iter()
        .map(|row| match row {
            Row::Kinematic(j) => vars[*j],
            Row::Sparse(entries) => {
                let terms: Vec<Id> = entries
                    .iter()
                    .map(|&(k, xi)| {
                        let c = g.constant(xi);
                        g.mul(c, theta[k])
                    })
                    .collect();
                g.sum(terms)
            }
        })
        .collect()
}
