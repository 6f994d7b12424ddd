//! The parameter metadata file (MAVLink component metadata,
//! COMP_METADATA_TYPE_PARAMETER, `parameter.schema.json`): every parameter
//! of [`definitions`] with its short and long description, units, range,
//! increment, decimal places, default, named values or bits, whether it
//! needs a restart, its group and its category.
//!
//! Made from the definitions alone, so it always describes the running
//! version. What the table does not say is derived here, the same way for
//! every row: the group is the name's first word (`BATT`, `BTN`, `SERVO`…,
//! digits dropped), the category "Standard" for parameters Neptunus acts
//! on and "Compatibility" for those that exist only for ground stations,
//! the short description the doc's first words, the decimal places those
//! the default and the range are written with (1 to 4 for REAL32, none
//! for integers), the increment one unit of the last decimal place, and a
//! parameter whose range is a single value is read-only. Pure: no I/O.

use serde_json::{Map, Value, json};

use super::defs::{ParamDef, ParamType, Use, definitions, format_value};

/// The file format's version (the schema's minimum).
pub const VERSION: u64 = 3;
/// The longest short description (the doc's first words are cut there).
pub const SHORT_MAX: usize = 80;

/// The parameter metadata as JSON text.
pub fn parameters_json() -> String {
    let parameters: Vec<Value> = definitions().iter().map(describe).collect();
    let file = json!({ "version": VERSION, "parameters": parameters });
    // serde_json writes a Value without failing.
    serde_json::to_string(&file).unwrap_or_default()
}

/// One parameter's entry.
fn describe(d: &ParamDef) -> Value {
    let mut p = Map::new();
    p.insert("name".into(), d.name.into());
    p.insert("type".into(), type_name(d.ty).into());
    p.insert("shortDesc".into(), short_description(d).into());
    p.insert("longDesc".into(), d.doc.into());
    if !d.units.is_empty() {
        p.insert("units".into(), d.units.into());
    }
    p.insert("default".into(), number(d.ty, d.default));
    p.insert("min".into(), number(d.ty, d.min));
    p.insert("max".into(), number(d.ty, d.max));
    let decimals = decimal_places(d);
    p.insert("decimalPlaces".into(), decimals.into());
    p.insert(
        "increment".into(),
        if d.ty.is_integer() {
            1.into()
        } else {
            number(d.ty, 10f64.powi(-(decimals as i32)))
        },
    );
    if d.reboot {
        p.insert("rebootRequired".into(), true.into());
    }
    if d.min == d.max {
        p.insert("readOnly".into(), true.into());
    }
    p.insert("group".into(), group(d.name).into());
    p.insert(
        "category".into(),
        match d.used {
            Use::Neptunus => "Standard",
            Use::Compat => "Compatibility",
        }
        .into(),
    );
    if !d.values.is_empty() {
        let values: Vec<Value> = d
            .values
            .iter()
            .map(|(v, text)| json!({ "value": v, "description": text }))
            .collect();
        p.insert("values".into(), values.into());
    }
    if !d.bitmask.is_empty() {
        let bits: Vec<Value> = d
            .bitmask
            .iter()
            .map(|(i, text)| json!({ "index": i, "description": text }))
            .collect();
        p.insert("bitmask".into(), bits.into());
    }
    Value::Object(p)
}

/// The schema's name of a wire type.
fn type_name(ty: ParamType) -> &'static str {
    match ty {
        ParamType::Int8 => "Int8",
        ParamType::Int16 => "Int16",
        ParamType::Int32 => "Int32",
        ParamType::Real32 => "Float",
    }
}

/// A value as the wire carries it: an integer, or the shortest decimal
/// that reads back to the same `f32`.
fn number(ty: ParamType, v: f64) -> Value {
    if ty.is_integer() {
        (v as i64).into()
    } else {
        let shortest: f64 = format_value(ty, v).parse().unwrap_or(v);
        serde_json::Number::from_f64(shortest).map_or(Value::Null, Value::Number)
    }
}

/// The short description: the table's, or the doc's first words — up to
/// its first full stop, opening parenthesis, colon or semicolon, at most
/// [`SHORT_MAX`] characters (cut at a word).
pub fn short_description(d: &ParamDef) -> String {
    if !d.short.is_empty() {
        return d.short.to_owned();
    }
    let doc = d.doc;
    let end = [". ", " (", ": ", "; ", ", which", " = "]
        .iter()
        .filter_map(|sep| doc.find(sep))
        .min()
        .unwrap_or(doc.len());
    let mut s = doc[..end].trim().trim_end_matches('.').to_owned();
    if s.chars().count() > SHORT_MAX {
        let cut: String = s.chars().take(SHORT_MAX).collect();
        s = match cut.rfind(' ') {
            Some(i) => cut[..i].to_owned(),
            None => cut,
        };
    }
    s
}

/// Decimal places to show: none for integers; for REAL32 as many as the
/// default and the range are written with, 1 to 4.
fn decimal_places(d: &ParamDef) -> u64 {
    if d.ty.is_integer() {
        return 0;
    }
    [d.default, d.min, d.max]
        .iter()
        .map(|&v| {
            let s = format_value(d.ty, v);
            match s.split_once('.') {
                Some((_, frac)) if !s.contains(['e', 'E']) => {
                    frac.trim_end_matches('0').len() as u64
                }
                _ => 0,
            }
        })
        .max()
        .unwrap_or(0)
        .clamp(1, 4)
}

/// The group: the name's first word without its digits (`BTN12_FUNCTION`
/// → `BTN`, `SR0_EXTRA1` → `SR`).
fn group(name: &str) -> String {
    let first = name.split('_').next().unwrap_or(name);
    let trimmed = first.trim_end_matches(|c: char| c.is_ascii_digit());
    if trimmed.is_empty() { first } else { trimmed }.to_owned()
}

#[cfg(test)]
#[allow(clippy::unwrap_used, clippy::expect_used)]
mod tests {
    use super::*;

    fn entry(name: &str) -> Value {
        let d = definitions().iter().find(|d| d.name == name).unwrap();
        describe(d)
    }

    #[test]
    fn entries_carry_what_the_table_says() {
        let e = entry("FS_GCS_ENABLE");
        assert_eq!(e["type"], "Int8");
        assert_eq!(e["default"], 2);
        assert_eq!(e["values"][4]["description"], "Enter surface mode");
        assert_eq!(e["group"], "FS");
        assert_eq!(e["category"], "Standard");
        let e = entry("BATT_LOW_VOLT");
        assert_eq!(e["type"], "Float");
        assert_eq!(e["units"], "V");
        assert_eq!(e["default"], 10.5);
        assert_eq!(e["decimalPlaces"], 1);
        assert_eq!(e["increment"], 0.1);
        let e = entry("ATC_RAT_PIT_D");
        assert_eq!(e["decimalPlaces"], 4);
        assert_eq!(e["category"], "Compatibility");
        assert_eq!(entry("SYSID_THISMAV")["rebootRequired"], true);
        assert_eq!(entry("FRAME_CONFIG")["readOnly"], true);
        assert_eq!(entry("BTN12_SFUNCTION")["group"], "BTN");
        assert_eq!(
            entry("BTN12_SFUNCTION")["shortDesc"],
            "Function of joystick button 12 while shift is held"
        );
        assert_eq!(entry("ARMING_CHECK")["bitmask"][0]["index"], 0);
    }

    #[test]
    fn every_parameter_has_a_short_and_a_long_description() {
        for d in definitions() {
            let short = short_description(d);
            assert!(
                !short.is_empty() && short.chars().count() <= SHORT_MAX,
                "{}: {short:?}",
                d.name
            );
            assert!(!d.doc.is_empty(), "{}", d.name);
        }
        let file: Value = serde_json::from_str(&parameters_json()).unwrap();
        assert_eq!(
            file["parameters"].as_array().unwrap().len(),
            definitions().len()
        );
    }

    #[test]
    fn every_named_value_lies_in_its_range() {
        for d in definitions() {
            for (v, _) in d.values {
                let v = f64::from(*v);
                assert!(d.min <= v && v <= d.max, "{} value {v}", d.name);
            }
        }
    }
}
