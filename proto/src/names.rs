//! What the wire API accepts as a name: the one rule the map server, the
//! simulator and the processes that take a name on their command line all
//! check, so a name one of them accepts none of the others refuses.
//!
//! ```
//! use deog_proto::names::{NameError, check_client_id, check_robot_name};
//!
//! assert_eq!(check_robot_name("scout-1"), Ok(()));
//! assert!(matches!(check_robot_name("scout 1"), Err(NameError::Character(' ', _))));
//! assert_eq!(check_client_id("carto/scout-1"), Ok(()));
//! ```

use thiserror::Error;

/// Longest name, bytes (every allowed character is one byte).
pub const MAX_NAME_LEN: usize = 128;

/// Why a name is refused. The text is the reason alone: the caller puts
/// the field it came from in front.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
pub enum NameError {
    /// The name is empty or longer than [`MAX_NAME_LEN`]; holds its length
    /// in bytes.
    #[error("must be 1 to 128 characters, got {0}")]
    Length(usize),
    /// The name holds a character outside the allowed set, which the
    /// second field spells out.
    #[error("character {0:?} is not allowed (use {1})")]
    Character(char, &'static str),
}

/// A robot name: 1 to 128 characters of `[A-Za-z0-9_.-]`.
pub fn check_robot_name(name: &str) -> Result<(), NameError> {
    check(name, &[], NAME_CHARACTERS)
}

/// A map name: the same rule as a robot's.
pub fn check_map_name(name: &str) -> Result<(), NameError> {
    check(name, &[], NAME_CHARACTERS)
}

/// An update client id (`UpdateBatch.client_id`): a name that may also hold
/// `/` and `:`, so a client can say whose it is (`carto/scout-1`).
pub fn check_client_id(id: &str) -> Result<(), NameError> {
    check(id, &['/', ':'], CLIENT_ID_CHARACTERS)
}

/// The characters of a name, as the refusal spells them.
const NAME_CHARACTERS: &str = "A-Z a-z 0-9 _ . -";
/// The characters of a client id.
const CLIENT_ID_CHARACTERS: &str = "A-Z a-z 0-9 _ . - / :";

fn check(name: &str, extra: &[char], allowed: &'static str) -> Result<(), NameError> {
    if name.is_empty() || name.len() > MAX_NAME_LEN {
        return Err(NameError::Length(name.len()));
    }
    match name
        .chars()
        .find(|c| !(c.is_ascii_alphanumeric() || matches!(c, '_' | '.' | '-') || extra.contains(c)))
    {
        Some(bad) => Err(NameError::Character(bad, allowed)),
        None => Ok(()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn length_is_counted_in_bytes_from_1_to_128() {
        assert_eq!(check_robot_name(""), Err(NameError::Length(0)));
        assert_eq!(check_robot_name(&"a".repeat(128)), Ok(()));
        assert_eq!(
            check_map_name(&"a".repeat(129)),
            Err(NameError::Length(129))
        );
        assert_eq!(
            check_robot_name(&"é".repeat(65)),
            Err(NameError::Length(130))
        );
    }

    #[test]
    fn only_ascii_letters_digits_and_three_marks_pass() {
        assert_eq!(check_robot_name("Scout_2.b-3"), Ok(()));
        assert_eq!(check_map_name("map1"), Ok(()));
        for bad in [' ', '/', ':', 'é', '\0', '*'] {
            let name = format!("a{bad}b");
            assert_eq!(
                check_robot_name(&name),
                Err(NameError::Character(bad, NAME_CHARACTERS))
            );
            assert_eq!(
                check_map_name(&name),
                Err(NameError::Character(bad, NAME_CHARACTERS))
            );
        }
    }

    #[test]
    fn client_ids_may_also_hold_slash_and_colon() {
        assert_eq!(check_client_id("carto/scout-1"), Ok(()));
        assert_eq!(check_client_id("import:map1"), Ok(()));
        assert_eq!(
            check_client_id("a b").unwrap_err().to_string(),
            "character ' ' is not allowed (use A-Z a-z 0-9 _ . - / :)"
        );
        assert_eq!(check_client_id(""), Err(NameError::Length(0)));
    }

    // The services send these texts to clients; they must read as before
    // the rule moved here.
    #[test]
    fn messages_read_as_the_services_always_sent_them() {
        assert_eq!(
            NameError::Length(0).to_string(),
            "must be 1 to 128 characters, got 0"
        );
        assert_eq!(
            NameError::Character(' ', NAME_CHARACTERS).to_string(),
            "character ' ' is not allowed (use A-Z a-z 0-9 _ . -)"
        );
    }
}
