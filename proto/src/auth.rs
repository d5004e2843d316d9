//! Optional bearer-token authentication, the one check both servers (the
//! map server and the simulator) put in front of their service.

use tonic::service::Interceptor;
use tonic::{Request, Status};

/// Accepts requests whose `authorization` metadata is `Bearer <token>`
/// (the scheme in any case, as HTTP's auth schemes are).
#[derive(Clone)]
pub struct BearerAuth {
    expected: Option<Vec<u8>>,
}

impl std::fmt::Debug for BearerAuth {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        // Never print the token.
        f.debug_struct("BearerAuth")
            .field("enabled", &self.expected.is_some())
            .finish()
    }
}

impl BearerAuth {
    /// Checks for `token`, or lets everything through when `None`.
    pub fn new(token: Option<String>) -> Self {
        Self {
            expected: token.map(|t| t.trim().as_bytes().to_vec()),
        }
    }

    /// Whether calls must carry a token.
    pub fn enabled(&self) -> bool {
        self.expected.is_some()
    }
}

/// The token of a `Bearer <token>` header value.
fn bearer_token(value: &[u8]) -> Option<&[u8]> {
    let (scheme, token) = value.split_at_checked(6)?;
    let token = token.strip_prefix(b" ")?;
    scheme.eq_ignore_ascii_case(b"bearer").then_some(token)
}

/// Whether `given` equals `expected`, in time that depends on the length of
/// `given` only: every byte of it is compared (against `expected` repeated)
/// whatever the lengths, so neither where the tokens differ nor the length
/// of the expected one shows in the time taken.
pub fn constant_time_eq(given: &[u8], expected: &[u8]) -> bool {
    // An empty expected token would leave nothing to cycle over; compare
    // against a zero byte instead (the length check still refuses).
    let pad = [0u8];
    let against = if expected.is_empty() {
        &pad[..]
    } else {
        expected
    };
    let differ = given
        .iter()
        .zip(against.iter().cycle())
        .fold(0u8, |acc, (x, y)| acc | (x ^ y));
    // Both folded in without a branch on either.
    let length_differs = u8::from(given.len() != expected.len());
    (differ | length_differs) == 0
}

impl Interceptor for BearerAuth {
    fn call(&mut self, request: Request<()>) -> Result<Request<()>, Status> {
        let Some(expected) = &self.expected else {
            return Ok(request);
        };
        match request.metadata().get("authorization") {
            Some(given)
                if bearer_token(given.as_bytes())
                    .is_some_and(|t| constant_time_eq(t, expected)) =>
            {
                Ok(request)
            }
            Some(_) => Err(Status::unauthenticated("the bearer token is not valid")),
            None => Err(Status::unauthenticated(
                "this server needs an `authorization: Bearer <token>` header",
            )),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::time::{Duration, Instant};

    #[test]
    fn compares_tokens_exactly() {
        assert!(constant_time_eq(b"Bearer abc", b"Bearer abc"));
        assert!(!constant_time_eq(b"Bearer abc", b"Bearer abd"));
        assert!(!constant_time_eq(b"Bearer abc", b"Bearer abcd"));
        assert!(!constant_time_eq(b"Bearer abcd", b"Bearer abc"));
        // A token repeated is not the token, though it matches the cycle.
        assert!(!constant_time_eq(b"abcabc", b"abc"));
        assert!(!constant_time_eq(b"", b"abc"));
        assert!(!constant_time_eq(b"abc", b""));
        assert!(constant_time_eq(b"", b""));
    }

    /// The fastest of `runs` comparisons of `given` with `expected`.
    fn fastest(given: &[u8], expected: &[u8], runs: usize) -> Duration {
        (0..runs)
            .map(|_| {
                let start = Instant::now();
                std::hint::black_box(constant_time_eq(
                    std::hint::black_box(given),
                    std::hint::black_box(expected),
                ));
                start.elapsed()
            })
            .min()
            .unwrap_or_default()
    }

    #[test]
    fn a_token_of_another_length_is_compared_in_full() {
        // It used to return at once on a length mismatch, which told an
        // attacker the token's length. A long guess of the wrong length
        // must take about as long as one of the right length.
        let expected = vec![b'k'; 32];
        let mut right_length = vec![b'k'; 1 << 20];
        *right_length.last_mut().expect("not empty") = b'x';
        let long_guess = vec![b'k'; (1 << 20) + 1];
        let same = fastest(&right_length, &right_length.clone(), 15);
        let other = fastest(&long_guess, &expected, 15);
        assert!(
            other * 10 >= same,
            "a wrong-length token took {other:?}, a right-length one {same:?}"
        );
    }

    #[test]
    fn refuses_missing_and_wrong_tokens() {
        let mut auth = BearerAuth::new(Some("s3cret\n".into()));
        assert!(auth.enabled());
        assert!(auth.call(Request::new(())).is_err());
        let mut wrong = Request::new(());
        wrong
            .metadata_mut()
            .insert("authorization", "Bearer nope".parse().unwrap());
        assert_eq!(
            auth.call(wrong).unwrap_err().code(),
            tonic::Code::Unauthenticated
        );
        let mut right = Request::new(());
        right
            .metadata_mut()
            .insert("authorization", "Bearer s3cret".parse().unwrap());
        assert!(auth.call(right).is_ok());
        for (value, ok) in [
            ("bearer s3cret", true),
            ("BEARER s3cret", true),
            ("Bearer  s3cret", false),
            ("Basic s3cret", false),
            ("s3cret", false),
            ("Bearer", false),
            ("Bearer s3cre", false),
            ("Bearer s3crets3cret", false),
        ] {
            let mut request = Request::new(());
            request
                .metadata_mut()
                .insert("authorization", value.parse().unwrap());
            assert_eq!(auth.call(request).is_ok(), ok, "{value:?}");
        }
        assert!(!BearerAuth::new(None).enabled());
        assert!(BearerAuth::new(None).call(Request::new(())).is_ok());
    }
}
