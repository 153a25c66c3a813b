//! Who may connect and what they may do: anonymous sessions only when `AllowAnonymous`
//! (as readers), user names and passwords checked against the users file
//! ([`crate::users`]), writes only for the `writer` role; every session may read the
//! Server object's diagnostics (as every DA client may read `_Diagnostics`).

use crate::node_manager::Roles;
use crate::users::{self, Role};
use opcua::server::authenticator::{
    user_pass_security_policy_id, AuthManager, CoreServerPermissions, Password, UserToken,
};
use opcua::server::ServerEndpoint;
use opcua::types::{Error, StatusCode, UAString, UserTokenPolicy, UserTokenType};
use std::collections::HashMap;
use std::path::PathBuf;
use std::sync::Mutex;

/// The user token of anonymous sessions (async-opcua's).
const ANONYMOUS: &str = "ANONYMOUS";

/// The front end's authenticator and write rights.
pub struct UsersAuth {
    users_file: PathBuf,
    allow_anonymous: bool,
    /// The role of each user who logged in (kept from the login for the session).
    roles: Mutex<HashMap<String, Role>>,
}

impl UsersAuth {
    pub fn new(users_file: PathBuf, allow_anonymous: bool) -> UsersAuth {
        UsersAuth {
            users_file,
            allow_anonymous,
            roles: Mutex::new(HashMap::new()),
        }
    }

    fn rejected(why: &str) -> Error {
        Error::new(StatusCode::BadIdentityTokenRejected, why.to_owned())
    }
}

impl Roles for UsersAuth {
    fn may_write(&self, token: &UserToken) -> bool {
        if token.0 == ANONYMOUS {
            return false;
        }
        let roles = self.roles.lock().unwrap_or_else(|p| p.into_inner());
        roles.get(&token.0) == Some(&Role::Writer)
    }
}

#[async_trait::async_trait]
impl AuthManager for UsersAuth {
    async fn authenticate_anonymous_token(&self, _endpoint: &ServerEndpoint) -> Result<(), Error> {
        if self.allow_anonymous {
            Ok(())
        } else {
            tracing::warn!("OPC UA: an anonymous session refused (AllowAnonymous is off)");
            Err(Self::rejected("anonymous sessions are off"))
        }
    }

    async fn authenticate_username_identity_token(
        &self,
        _endpoint: &ServerEndpoint,
        username: &str,
        password: &Password,
    ) -> Result<UserToken, Error> {
        let path = self.users_file.clone();
        let name = username.to_owned();
        let pass = password.get().to_owned();
        // PBKDF2 takes a while by design: off the runtime's worker threads.
        let found = tokio::task::spawn_blocking(move || {
            let users = users::load(&path)?;
            Ok::<_, String>(
                users
                    .into_iter()
                    .find(|u| u.name == name)
                    .filter(|u| u.verify(&pass))
                    .map(|u| u.role),
            )
        })
        .await
        .map_err(|_| Self::rejected("login failed"))?;
        match found {
            Ok(Some(role)) => {
                tracing::info!("OPC UA: user {username} logged in ({})", role.name());
                self.roles
                    .lock()
                    .unwrap_or_else(|p| p.into_inner())
                    .insert(username.to_owned(), role);
                Ok(UserToken(username.to_owned()))
            }
            Ok(None) => {
                tracing::warn!(
                    "OPC UA: login of user {username:?} refused (unknown user or wrong password)"
                );
                Err(Self::rejected("unknown user or wrong password"))
            }
            Err(e) => {
                tracing::error!("OPC UA: {e}");
                Err(Self::rejected("login failed"))
            }
        }
    }

    fn user_token_policies(&self, endpoint: &ServerEndpoint) -> Vec<UserTokenPolicy> {
        let mut out = vec![UserTokenPolicy {
            policy_id: user_pass_security_policy_id(endpoint),
            token_type: UserTokenType::UserName,
            issued_token_type: UAString::null(),
            issuer_endpoint_url: UAString::null(),
            security_policy_uri: UAString::null(),
        }];
        if self.allow_anonymous {
            out.push(UserTokenPolicy {
                policy_id: UAString::from("anonymous"),
                token_type: UserTokenType::Anonymous,
                issued_token_type: UAString::null(),
                issuer_endpoint_url: UAString::null(),
                security_policy_uri: UAString::null(),
            });
        }
        out
    }

    fn core_permissions(&self, _token: &UserToken) -> CoreServerPermissions {
        CoreServerPermissions {
            read_diagnostics: true,
        }
    }
}
