//! The parameter table the user guide's parameter page
//! (`docs/guide/src/parameters.md`) embeds between `<!-- params:begin -->`
//! and `<!-- params:end -->`, generated from the definitions.
//! `tests/params.rs` checks that the page holds exactly this text (and
//! rewrites it with `UPDATE_GUIDE=1`); this module never writes a file.

use std::fmt::Write as _;

use super::defs::{Use, definitions, format_value};

/// Markdown table of every parameter, for the user guide.
pub fn markdown_table() -> String {
    let mut out = String::from(
        "| Name | Type | Default | Range | Units | Used | Description |\n\
         |---|---|---|---|---|---|---|\n",
    );
    for d in definitions() {
        let range = if d.min == d.max {
            format!("fixed {}", format_value(d.ty, d.min))
        } else {
            format!(
                "{} … {}",
                format_value(d.ty, d.min),
                format_value(d.ty, d.max)
            )
        };
        let used = match d.used {
            Use::Neptunus => "Neptunus",
            Use::Compat => "compat only",
        };
        let _ = writeln!(
            out,
            "| `{}` | {} | {} | {} | {} | {} | {} |",
            d.name,
            d.ty.name(),
            format_value(d.ty, d.default),
            range,
            d.units,
            used,
            d.doc.replace('|', "\\|")
        );
    }
    out
}
