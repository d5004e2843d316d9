//! The one way figures are written as JSON: serde records, pretty-printed,
//! a closing newline.

use serde::Serialize;

/// `value` as pretty-printed JSON ending with a newline. Non-finite
/// numbers become `null`; fails only for values JSON cannot hold (maps
/// with keys that are not strings).
pub fn pretty_json(value: &impl Serialize) -> Result<String, serde_json::Error> {
    let mut text = serde_json::to_string_pretty(value)?;
    text.push('\n');
    Ok(text)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pretty_with_a_newline_and_nan_as_null() {
        #[derive(Serialize)]
        struct Figures {
            rate: f64,
            missing: f64,
        }
        let text = pretty_json(&Figures {
            rate: 1.5,
            missing: f64::NAN,
        })
        .expect("serialises");
        assert_eq!(text, "{\n  \"rate\": 1.5,\n  \"missing\": null\n}\n");
    }
}
