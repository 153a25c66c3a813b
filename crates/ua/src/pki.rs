//! The certificate store's trust operation: `ServerCTOPC pki trust FILE` copies a client
//! certificate (DER or PEM) into `trusted/` under the name the store looks it up by, and
//! removes it from `rejected/` when it was there.

use opcua::crypto::{CertificateStore, X509};
use std::path::{Path, PathBuf};

/// The largest certificate file read.
const MAX_CERT_BYTES: u64 = 64 * 1024;

/// Trusts the certificate in `file`: the path it was stored at.
pub fn trust(pki_dir: &Path, file: &Path) -> Result<PathBuf, String> {
    let len = std::fs::metadata(file)
        .map_err(|e| format!("cannot read {}: {e}", file.display()))?
        .len();
    if len > MAX_CERT_BYTES {
        return Err(format!("{} is too large for a certificate", file.display()));
    }
    let bytes = std::fs::read(file).map_err(|e| format!("cannot read {}: {e}", file.display()))?;
    let cert = X509::from_der(&bytes)
        .or_else(|_| X509::from_pem(&bytes))
        .map_err(|e| {
            format!(
                "{} is not an X.509 certificate (DER or PEM): {e:?}",
                file.display()
            )
        })?;
    let name = CertificateStore::cert_file_name(&cert);
    let trusted = pki_dir.join("trusted");
    std::fs::create_dir_all(&trusted)
        .map_err(|e| format!("cannot make {}: {e}", trusted.display()))?;
    let target = trusted.join(&name);
    let der = cert
        .to_der()
        .map_err(|e| format!("cannot encode the certificate: {e:?}"))?;
    std::fs::write(&target, der).map_err(|e| format!("cannot write {}: {e}", target.display()))?;
    let rejected = pki_dir.join("rejected").join(&name);
    if rejected.exists() {
        let _ = std::fs::remove_file(&rejected);
    }
    Ok(target)
}
