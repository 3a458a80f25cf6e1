//! Boundary conditions that contradict each other although each is valid on
//! its own (issue 41, item 6): a fixed or prescribed grid line that holds the
//! nodes a rigid body drives, and two pressures on the same side of a body,
//! which would add up. Each is refused naming both entries.

use super::schema::*;
use super::validation::FieldError;

/// The part of a body's top that a `[[bc.rigid]]` entry drives: the line
/// y = `top` from `x_from` to `x_to` (m), of the body named `body`.
struct DrivenTop {
    /// Name of the driven body.
    body: String,
    /// Height of the body's top, m.
    top: f64,
    /// Start of the driven part of the top, m.
    x_from: f64,
    /// End of the driven part of the top, m.
    x_to: f64,
}

/// A fixed or prescribed condition on one displacement component of a grid
/// line: u = D(t) (rate + gradient · x), D of its start ramp (a fixed entry
/// has rate 0 and no gradient).
pub(super) struct LineCondition {
    /// The entry, e.g. `bc.fixed[2]`.
    pub(super) field: String,
    /// The line as written, e.g. `y=0.2`.
    pub(super) text: String,
    /// The parsed line.
    pub(super) line: GridLine,
    /// The component held or driven.
    pub(super) component: Component,
    /// Rate at the origin, m per unit time.
    pub(super) rate: f64,
    /// Spatial gradient of the rate, 1 per unit time.
    pub(super) gradient: [f64; 2],
    /// Start ramp time (0 for a fixed entry).
    pub(super) ramp_time: f64,
}

impl LineCondition {
    /// The rate the condition gives the node at `x`, m per unit time.
    pub(super) fn rate_at(&self, x: [f64; 2]) -> f64 {
        self.rate + self.gradient[0] * x[0] + self.gradient[1] * x[1]
    }

    /// What the condition asks of its component at `x`, for messages:
    /// `holds the y displacement there at 0`, or `drives …` with its rate
    /// (and its ramp time when that is what differs).
    fn describe(&self, x: [f64; 2], other_ramp: f64) -> String {
        let dof = component_name(self.component);
        if self.field.starts_with("bc.fixed") {
            return format!("holds the {dof} displacement there at 0");
        }
        let ramp = if self.ramp_time == other_ramp {
            String::new()
        } else {
            format!(" (ramp time {})", self.ramp_time)
        };
        format!(
            "drives the {dof} displacement there at {} m per unit time{ramp}",
            self.rate_at(x)
        )
    }
}

/// Name of a displacement component for messages.
fn component_name(component: Component) -> &'static str {
    match component {
        Component::X => "x",
        Component::Y => "y",
    }
}

/// Whether two rates (with their ramp times) give a dof different motions.
fn rates_differ(a: f64, ramp_a: f64, b: f64, ramp_b: f64) -> bool {
    let moving = a != 0.0 || b != 0.0;
    (a - b).abs() > 1e-9 * (a.abs() + b.abs()) || (moving && ramp_a != ramp_b)
}

impl Scene {
    /// Every fixed and prescribed entry, one per line and component (lines
    /// that do not parse are reported by the line checks).
    pub(super) fn line_conditions(&self) -> Vec<LineCondition> {
        let mut conditions = Vec::new();
        for (i, f) in self.bc.fixed.iter().enumerate() {
            let Ok(line) = GridLine::parse(&f.line) else {
                continue;
            };
            for &component in &f.dofs {
                conditions.push(LineCondition {
                    field: format!("bc.fixed[{i}]"),
                    text: f.line.clone(),
                    line,
                    component,
                    rate: 0.0,
                    gradient: [0.0; 2],
                    ramp_time: 0.0,
                });
            }
        }
        for (i, p) in self.bc.prescribed.iter().enumerate() {
            let Ok(line) = GridLine::parse(&p.line) else {
                continue;
            };
            conditions.push(LineCondition {
                field: format!("bc.prescribed[{i}]"),
                text: p.line.clone(),
                line,
                component: p.dof,
                rate: p.rate,
                gradient: p.gradient,
                ramp_time: p.ramp_time,
            });
        }
        conditions
    }

    /// The top of the body that rigid entry `rigid` drives, within its
    /// footprint (`None` when the body or the overlap does not exist: other
    /// checks report those). The top is the body's highest level; a polygon
    /// body is driven between its highest vertices.
    fn driven_top(&self, rigid: &RigidSpec) -> Option<DrivenTop> {
        let index = self.body_index(rigid.body.as_deref())?;
        let body = &self.body[index];
        let outline = body.outline();
        let top = outline
            .iter()
            .map(|v| v[1])
            .fold(f64::NEG_INFINITY, f64::max);
        let tol = 1e-9 * self.grid.cell_size.abs().max(top.abs());
        let at_top = outline.iter().filter(|v| (v[1] - top).abs() <= tol);
        let (lo, hi) = at_top.fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| {
            (lo.min(v[0]), hi.max(v[0]))
        });
        let (x_from, x_to) = (rigid.footprint[0].max(lo), rigid.footprint[1].min(hi));
        (top.is_finite() && x_from <= x_to).then(|| DrivenTop {
            body: body.name_or_default(index),
            top,
            x_from,
            x_to,
        })
    }

    /// A `[[bc.rigid]]` entry drives the top of its body (theory D40–D41); a
    /// fixed or prescribed line there that gives a component the body moves
    /// (velocity ≠ 0) another motion contradicts it. Refused naming both
    /// entries: a line along the top compared at both ends of the driven
    /// part, a vertical line where it meets the top.
    pub(super) fn validate_rigid_line_conflicts(&self, e: &mut Vec<FieldError>) {
        let conditions = self.line_conditions();
        for (r, rigid) in self.bc.rigid.iter().enumerate() {
            let Some(driven) = self.driven_top(rigid) else {
                continue;
            };
            let tol = 1e-9 * self.grid.cell_size.abs().max(driven.top.abs());
            let mut named: Vec<&str> = Vec::new();
            for c in &conditions {
                let nodes: Vec<[f64; 2]> = match c.line.axis {
                    1 if (c.line.value - driven.top).abs() <= tol => {
                        vec![[driven.x_from, driven.top], [driven.x_to, driven.top]]
                    }
                    0 if c.line.value >= driven.x_from - tol
                        && c.line.value <= driven.x_to + tol =>
                    {
                        vec![[c.line.value, driven.top]]
                    }
                    _ => continue,
                };
                let velocity = rigid.velocity[c.component.index()];
                if velocity == 0.0 {
                    continue; // the body only holds this component (its roughness)
                }
                let clash = nodes
                    .into_iter()
                    .find(|x| rates_differ(velocity, rigid.ramp_time, c.rate_at(*x), c.ramp_time));
                if let Some(x) = clash.filter(|_| !named.contains(&c.field.as_str())) {
                    named.push(&c.field);
                    e.push(FieldError {
                        field: format!("bc.rigid[{r}]"),
                        message: rigid_conflict_message(&driven, rigid, c, x),
                    });
                }
            }
        }
    }

    /// Two `[[bc.pressure]]` entries on the same side of a box body, or on
    /// overlapping edges of a polygon body, would add up on the shared part:
    /// refused naming both (one entry with the total says what is meant).
    pub(super) fn validate_pressure_duplicates(&self, e: &mut Vec<FieldError>) {
        let pressures = &self.bc.pressure;
        for (j, b) in pressures.iter().enumerate() {
            let Some(body) = self.body_index(b.body.as_deref()) else {
                continue;
            };
            let earlier = pressures[..j]
                .iter()
                .enumerate()
                .filter(|(_, a)| self.body_index(a.body.as_deref()) == Some(body));
            for (i, a) in earlier {
                let Some(shared) = shared_place(a, b) else {
                    continue;
                };
                e.push(FieldError {
                    field: format!("bc.pressure[{j}]"),
                    message: format!(
                        "loads {shared} of body `{}`, which bc.pressure[{i}] loads too: the pressures {} and {} kPa would add up to {} kPa there; give one entry with the pressure meant",
                        self.body[body].name_or_default(body),
                        a.p,
                        b.p,
                        a.p + b.p
                    ),
                });
            }
        }
    }
}

/// The message of `Scene::validate_rigid_line_conflicts`: where, what
/// each entry asks of the dof, and what to do.
fn rigid_conflict_message(
    driven: &DrivenTop,
    rigid: &RigidSpec,
    c: &LineCondition,
    x: [f64; 2],
) -> String {
    let where_ = if c.line.axis == 1 {
        format!(
            "the top of body `{}` (y = {} m, x from {} to {} m)",
            driven.body, driven.top, driven.x_from, driven.x_to
        )
    } else {
        format!(
            "the point ({}, {}) m where `{}` meets the top of body `{}`",
            x[0], x[1], c.text, driven.body
        )
    };
    let ramp = if rigid.ramp_time == c.ramp_time {
        String::new()
    } else {
        format!(" (ramp time {})", rigid.ramp_time)
    };
    format!(
        "`{}` moves {where_} in {} at {} m per unit time{ramp}, but {} (`{}`) {}: one dof takes one condition; remove one of the two or make them agree",
        rigid.name,
        component_name(c.component),
        rigid.velocity[c.component.index()],
        c.field,
        c.text,
        c.describe(x, rigid.ramp_time)
    )
}

/// The place two pressure entries on one body both load, for messages
/// (`the top side`, `edges 2 to 3`), or `None` when they load different parts.
fn shared_place(a: &PressureSpec, b: &PressureSpec) -> Option<String> {
    match (a.side, b.side, a.edges, b.edges) {
        (Some(sa), Some(sb), _, _) if sa == sb => Some(format!(
            "the {} side",
            match sa {
                Side::Left => "left",
                Side::Right => "right",
                Side::Bottom => "bottom",
                Side::Top => "top",
            }
        )),
        (_, _, Some([a0, a1]), Some([b0, b1])) if a0.max(b0) <= a1.min(b1) => {
            let (first, last) = (a0.max(b0), a1.min(b1));
            Some(if first == last {
                format!("edge {first}")
            } else {
                format!("edges {first} to {last}")
            })
        }
        _ => None,
    }
}
