//! Optional bearer-token authentication of the map service.

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
}

/// The token of a `Bearer <token>` header value.
fn bearer_token(value: &[u8]) -> Option<&[u8]> {
    let (scheme, token) = value.split_at_checked(6)?;
    let token = token.strip_prefix(b" ")?;
    scheme.eq_ignore_ascii_case(b"bearer").then_some(token)
}

/// Compares in time independent of where the inputs differ.
fn constant_time_eq(a: &[u8], b: &[u8]) -> bool {
    a.len() == b.len() && a.iter().zip(b).fold(0u8, |acc, (x, y)| acc | (x ^ y)) == 0
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

    #[test]
    fn compares_tokens_exactly() {
        assert!(constant_time_eq(b"Bearer abc", b"Bearer abc"));
        assert!(!constant_time_eq(b"Bearer abc", b"Bearer abd"));
        assert!(!constant_time_eq(b"Bearer abc", b"Bearer abcd"));
    }

    #[test]
    fn refuses_missing_and_wrong_tokens() {
        let mut auth = BearerAuth::new(Some("s3cret\n".into()));
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
        ] {
            let mut request = Request::new(());
            request
                .metadata_mut()
                .insert("authorization", value.parse().unwrap());
            assert_eq!(auth.call(request).is_ok(), ok, "{value:?}");
        }
        assert!(BearerAuth::new(None).call(Request::new(())).is_ok());
    }
}
