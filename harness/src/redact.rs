//! Secrets kept out of what is shown: logs, reports, command lines.

/// `url` with any password replaced by `***` (`scheme://user:***@host…`);
/// anything that is not such a URL comes back as it is.
pub fn url_without_password(url: &str) -> String {
    let Some((scheme, rest)) = url.split_once("://") else {
        return url.to_string();
    };
    let (authority, tail) = match rest.find(['/', '?']) {
        Some(at) => rest.split_at(at),
        None => (rest, ""),
    };
    let Some((credentials, hosts)) = authority.rsplit_once('@') else {
        return url.to_string();
    };
    let Some((user, _password)) = credentials.split_once(':') else {
        return url.to_string();
    };
    format!("{scheme}://{user}:***@{hosts}{tail}")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_password_never_shows() {
        assert_eq!(
            url_without_password("postgres://deog:s3cret@a,b:5433/maps?x=1"),
            "postgres://deog:***@a,b:5433/maps?x=1"
        );
        assert_eq!(
            url_without_password("postgresql://deog@db/maps"),
            "postgresql://deog@db/maps"
        );
        assert_eq!(url_without_password("deog-data"), "deog-data");
        assert_eq!(
            url_without_password("postgres://db/m?u=a@b"),
            "postgres://db/m?u=a@b"
        );
    }
}
