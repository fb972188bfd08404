//! Bearer-token authentication: an interceptor per service checks `authorization: Bearer <token>` against
//! the configured tokens; admin services need an `admin` token. Tokens are kept only as SHA-256 digests, and
//! a presented token's digest is compared with every configured one in constant time, so how long a check
//! takes says nothing about which token, or how much of one, matched.

use crate::metrics::Metrics;
use sha2::{Digest, Sha256};
use std::sync::Arc;
use subtle::ConstantTimeEq;
use tonic::{Request, Status};

/// What a token may do.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub enum Role {
    /// Safety and model queries.
    User,
    /// Everything, including ModelAdminService.
    Admin,
}

/// A bad token entry.
#[derive(Debug, thiserror::Error)]
#[error("token entry {line}: {reason} (expected `user:<token>` or `admin:<token>`)")]
pub struct TokenError {
    /// 1-based entry number.
    pub line: usize,
    /// What is wrong.
    pub reason: String,
}

/// The configured tokens; empty means authentication is off.
#[derive(Debug, Default)]
pub struct Tokens {
    digests: Vec<([u8; 32], Role)>,
}

fn digest(token: &str) -> [u8; 32] {
    Sha256::digest(token.as_bytes()).into()
}

impl Tokens {
    /// Parses `role:token` entries; blank entries and `#` comments are skipped.
    pub fn parse(entries: &[String]) -> Result<Tokens, TokenError> {
        let mut digests: Vec<([u8; 32], Role)> = Vec::new();
        for (i, entry) in entries.iter().enumerate() {
            let entry = entry.trim();
            if entry.is_empty() || entry.starts_with('#') {
                continue;
            }
            let fail = |reason: &str| TokenError { line: i + 1, reason: reason.into() };
            let (role, token) = entry.split_once(':').ok_or_else(|| fail("no `:`"))?;
            let role = match role.trim() {
                "user" => Role::User,
                "admin" => Role::Admin,
                _ => return Err(fail("unknown role")),
            };
            let token = token.trim();
            if token.len() < 8 {
                return Err(fail("token shorter than 8 characters"));
            }
            let token_digest = digest(token);
            match digests.iter_mut().find(|(d, _)| *d == token_digest) {
                Some(entry) => entry.1 = role,
                None => digests.push((token_digest, role)),
            }
        }
        Ok(Tokens { digests })
    }

    /// True when no token is configured (every call is allowed).
    pub fn is_empty(&self) -> bool {
        self.digests.is_empty()
    }

    /// Number of tokens per role: (user, admin).
    pub fn counts(&self) -> (usize, usize) {
        let admins = self.digests.iter().filter(|(_, r)| *r == Role::Admin).count();
        (self.digests.len() - admins, admins)
    }

    fn role_of(&self, token: &str) -> Option<Role> {
        let presented = digest(token);
        // Every entry is compared, whatever matched before: no early exit.
        let mut found = None;
        for (configured, role) in &self.digests {
            if bool::from(configured.ct_eq(&presented)) {
                found = Some(*role);
            }
        }
        found
    }
}

/// The interceptor guarding one service: lets a call through when its token's role is at least `required`.
#[derive(Clone)]
pub struct Guard {
    tokens: Arc<Tokens>,
    required: Role,
    metrics: Arc<Metrics>,
}

impl Guard {
    /// A guard requiring `required`.
    pub fn new(tokens: Arc<Tokens>, required: Role, metrics: Arc<Metrics>) -> Self {
        Self { tokens, required, metrics }
    }

    fn check(&self, request: &Request<()>) -> Result<(), Status> {
        if self.tokens.is_empty() {
            return Ok(());
        }
        let Some(header) = request.metadata().get("authorization") else {
            return Err(Status::unauthenticated("missing `authorization: Bearer <token>` metadata"));
        };
        let token = header
            .to_str()
            .ok()
            .and_then(|h| h.strip_prefix("Bearer ").or_else(|| h.strip_prefix("bearer ")))
            .ok_or_else(|| Status::unauthenticated("`authorization` metadata must be `Bearer <token>`"))?;
        match self.tokens.role_of(token.trim()) {
            None => Err(Status::unauthenticated("the bearer token is not recognised")),
            Some(role) if role < self.required => {
                Err(Status::permission_denied("this service needs an admin token; the token given is a user token"))
            }
            Some(_) => Ok(()),
        }
    }
}

impl tonic::service::Interceptor for Guard {
    fn call(&mut self, request: Request<()>) -> Result<Request<()>, Status> {
        self.check(&request).map(|()| request).inspect_err(|status| {
            self.metrics.auth_failure(status.code());
            tracing::warn!(code = ?status.code(), reason = status.message(), "call refused");
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn entries_parse_and_errors_name_the_entry() {
        let ok =
            Tokens::parse(&["# ops".into(), "".into(), "user:abcdefgh".into(), "admin: 12345678 ".into()]).unwrap();
        assert_eq!(ok.counts(), (1, 1));
        assert_eq!(ok.role_of("12345678"), Some(Role::Admin));
        assert_eq!(ok.role_of("abcdefgh"), Some(Role::User));
        assert_eq!(ok.role_of("abcdefgi"), None);
        let e = Tokens::parse(&["user:abcdefgh".into(), "root:abcdefgh".into()]).unwrap_err();
        assert_eq!(e.line, 2);
        assert!(e.to_string().contains("unknown role"));
        assert!(Tokens::parse(&["user:short".into()]).is_err());
        assert!(Tokens::parse(&["userabcdefgh".into()]).is_err());
        // A token given twice counts once, with its last role.
        let twice = Tokens::parse(&["user:abcdefgh".into(), "admin:abcdefgh".into()]).unwrap();
        assert_eq!((twice.counts(), twice.role_of("abcdefgh")), ((0, 1), Some(Role::Admin)));
    }
}
