//! The asix link's TLS (protocol version 2, `docs/asix-net-protocol.md` section 3): TLS 1.3
//! only, both sides with a certificate (mutual TLS), each side pinning the certificates it
//! accepts by SHA-256 fingerprint or by a CA.
//!
//! - [`Identity`]: a side's certificate chain and private key (PEM files, or made by
//!   [`generate`] for `asix-sim --gen-cert`).
//! - [`Trust`]: which peers are accepted. A pinned fingerprint's certificate is still
//!   checked as its own trust anchor (signature, validity period, key usage), so an expired
//!   pinned certificate is refused like an expired CA-issued one.
//! - [`client_config`], [`server_config`]: the rustls configurations (ring provider, TLS 1.3).
//! - The peer's identity after the handshake is `cert:<fingerprint>` ([`peer_identity`]),
//!   the fingerprint as 64 lowercase hex digits.

use std::fmt;
use std::path::Path;
use std::sync::Arc;

use rustls::client::danger::{HandshakeSignatureValid, ServerCertVerified, ServerCertVerifier};
use rustls::crypto::{CryptoProvider, WebPkiSupportedAlgorithms};
use rustls::pki_types::pem::PemObject;
use rustls::pki_types::{CertificateDer, PrivateKeyDer, ServerName, TrustAnchor, UnixTime};
use rustls::server::danger::{ClientCertVerified, ClientCertVerifier};
use rustls::{
    CertificateError, DigitallySignedStruct, DistinguishedName, Error, SignatureScheme,
    SupportedProtocolVersion,
};

/// A certificate's SHA-256 fingerprint (of its DER encoding).
pub type Fingerprint = [u8; 32];

/// The server name the client puts in its TLS ClientHello. Servers are identified by their
/// certificate (pinned fingerprint or CA), never by this name.
pub const SNI_NAME: &str = "asix-server.invalid";

/// The one protocol version of the link.
static TLS13_ONLY: &[&SupportedProtocolVersion] = &[&rustls::version::TLS13];

/// The SHA-256 fingerprint of a certificate.
pub fn fingerprint(cert: &CertificateDer<'_>) -> Fingerprint {
    let d = ring::digest::digest(&ring::digest::SHA256, cert.as_ref());
    let mut fp = [0u8; 32];
    fp.copy_from_slice(d.as_ref());
    fp
}

/// A fingerprint as 64 lowercase hex digits.
pub fn fingerprint_hex(fp: &Fingerprint) -> String {
    fp.iter().map(|b| format!("{b:02x}")).collect()
}

/// The identity of a peer known by its certificate: `cert:<64 hex digits>`.
pub fn identity_of(fp: &Fingerprint) -> String {
    format!("cert:{}", fingerprint_hex(fp))
}

/// Parses a fingerprint: 64 hex digits, upper or lower case, optionally separated by `:`
/// or blanks (as certificate tools print them), optionally after `cert:` or `sha256:`.
pub fn parse_fingerprint(s: &str) -> Result<Fingerprint, String> {
    let t = s.trim();
    let t = t
        .strip_prefix("cert:")
        .or_else(|| t.strip_prefix("sha256:"))
        .or_else(|| t.strip_prefix("SHA256:"))
        .unwrap_or(t);
    let digits: Vec<u8> = t
        .bytes()
        .filter(|b| !matches!(b, b':' | b' ' | b'\t'))
        .collect();
    let bad = || format!("{s:?} is not a SHA-256 fingerprint (64 hex digits)");
    if digits.len() != 64 {
        return Err(bad());
    }
    let mut fp = [0u8; 32];
    for (i, pair) in digits.chunks(2).enumerate() {
        let text = std::str::from_utf8(pair).map_err(|_| bad())?;
        fp[i] = u8::from_str_radix(text, 16).map_err(|_| bad())?;
    }
    Ok(fp)
}

/// Parses a comma-separated list of fingerprints.
pub fn parse_fingerprints(s: &str) -> Result<Vec<Fingerprint>, String> {
    s.split(',')
        .filter(|x| !x.trim().is_empty())
        .map(parse_fingerprint)
        .collect()
}

/// Why TLS settings could not be made.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{0}")]
pub struct TlsError(pub String);

/// A side's certificate chain (its own certificate first) and private key.
#[derive(Clone)]
pub struct Identity {
    chain: Vec<CertificateDer<'static>>,
    key: Arc<PrivateKeyDer<'static>>,
}

impl fmt::Debug for Identity {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        // Never the key.
        write!(f, "Identity({})", identity_of(&self.fingerprint()))
    }
}

impl Identity {
    /// From PEM text: one or more certificates (own first) and a PKCS#8, PKCS#1 or SEC1 key.
    pub fn from_pem(cert_pem: &[u8], key_pem: &[u8]) -> Result<Identity, TlsError> {
        let chain = CertificateDer::pem_slice_iter(cert_pem)
            .collect::<Result<Vec<_>, _>>()
            .map_err(|e| TlsError(format!("certificate: {e}")))?;
        if chain.is_empty() {
            return Err(TlsError("no certificate in the PEM text".into()));
        }
        let key = PrivateKeyDer::from_pem_slice(key_pem)
            .map_err(|e| TlsError(format!("private key: {e}")))?;
        // The key must be usable and belong to the certificate.
        let provider = provider();
        let signing = provider
            .key_provider
            .load_private_key(key.clone_key())
            .map_err(|e| TlsError(format!("private key: {e}")))?;
        let ck = rustls::sign::CertifiedKey::new(chain.clone(), signing);
        ck.keys_match()
            .map_err(|e| TlsError(format!("the key does not belong to the certificate: {e}")))?;
        Ok(Identity {
            chain,
            key: Arc::new(key),
        })
    }

    /// From a certificate file and a key file (PEM); a WARN when the key file is open to
    /// its group or others (`ctopc_runtime::secret_file`).
    pub fn load(cert_file: &Path, key_file: &Path) -> Result<Identity, TlsError> {
        let cert = std::fs::read(cert_file)
            .map_err(|e| TlsError(format!("{}: {e}", cert_file.display())))?;
        let key = std::fs::read(key_file)
            .map_err(|e| TlsError(format!("{}: {e}", key_file.display())))?;
        ctopc_runtime::secret_file::warn_if_exposed(key_file, "the asix link's private key");
        Identity::from_pem(&cert, &key).map_err(|TlsError(m)| {
            TlsError(format!(
                "{} / {}: {m}",
                cert_file.display(),
                key_file.display()
            ))
        })
    }

    /// The SHA-256 fingerprint of the own certificate (what the other side pins).
    pub fn fingerprint(&self) -> Fingerprint {
        fingerprint(&self.chain[0])
    }

    pub fn certificate(&self) -> &CertificateDer<'static> {
        &self.chain[0]
    }
}

/// A key pair and self-signed certificate made by [`generate`], as PEM text.
pub struct Generated {
    pub identity: Identity,
    pub cert_pem: String,
    pub key_pem: String,
}

/// Makes an ECDSA P-256 key pair and a self-signed certificate for `name` (subject common
/// name and DNS name), usable as server and as client (both extended key usages), valid
/// from `not_before` to `not_after` (years; `None`: from yesterday for 20 years).
pub fn generate(name: &str, validity: Option<(i32, i32)>) -> Result<Generated, TlsError> {
    let err = |e: rcgen::Error| TlsError(format!("certificate generation: {e}"));
    let key = rcgen::KeyPair::generate().map_err(err)?;
    let dns = if rustls::pki_types::DnsName::try_from(name).is_ok() {
        vec![name.to_owned()]
    } else {
        Vec::new()
    };
    let mut p = rcgen::CertificateParams::new(dns).map_err(err)?;
    p.distinguished_name = rcgen::DistinguishedName::new();
    p.distinguished_name
        .push(rcgen::DnType::CommonName, name.to_owned());
    p.extended_key_usages = vec![
        rcgen::ExtendedKeyUsagePurpose::ServerAuth,
        rcgen::ExtendedKeyUsagePurpose::ClientAuth,
    ];
    match validity {
        Some((from, to)) => {
            p.not_before = rcgen::date_time_ymd(from, 1, 1);
            p.not_after = rcgen::date_time_ymd(to, 1, 1);
        }
        None => {
            let now = std::time::SystemTime::now()
                .duration_since(std::time::UNIX_EPOCH)
                .map(|d| d.as_secs())
                .unwrap_or(0);
            // Civil year of now (approximate is enough: a day's margin either side).
            let year = 1970 + (now / 31_556_952) as i32;
            p.not_before = rcgen::date_time_ymd(year - 1, 1, 1);
            p.not_after = rcgen::date_time_ymd(year + 20, 1, 1);
        }
    }
    let cert = p.self_signed(&key).map_err(err)?;
    let cert_pem = cert.pem();
    let key_pem = key.serialize_pem();
    let identity = Identity::from_pem(cert_pem.as_bytes(), key_pem.as_bytes())?;
    Ok(Generated {
        identity,
        cert_pem,
        key_pem,
    })
}

/// Which peer certificates a side accepts.
#[derive(Clone)]
pub enum Trust {
    /// Only certificates with these fingerprints (each checked as its own anchor).
    Fingerprints(Vec<Fingerprint>),
    /// Certificates issued by one of these CAs (PEM file of the CA certificates).
    Ca(Arc<Vec<TrustAnchor<'static>>>),
    /// Any certificate (still checked as its own anchor: signature, validity, usage). A
    /// server that accepts any client still knows each client's identity; a client never
    /// uses this.
    AnyCertificate,
}

impl fmt::Debug for Trust {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Trust::Fingerprints(v) => f
                .debug_list()
                .entries(v.iter().map(fingerprint_hex))
                .finish(),
            Trust::Ca(a) => write!(f, "Ca({} anchors)", a.len()),
            Trust::AnyCertificate => f.write_str("AnyCertificate"),
        }
    }
}

impl Trust {
    /// The CA certificates of a PEM file.
    pub fn ca_file(path: &Path) -> Result<Trust, TlsError> {
        let pem = std::fs::read(path).map_err(|e| TlsError(format!("{}: {e}", path.display())))?;
        Trust::ca_pem(&pem).map_err(|TlsError(m)| TlsError(format!("{}: {m}", path.display())))
    }

    /// The CA certificates of PEM text.
    pub fn ca_pem(pem: &[u8]) -> Result<Trust, TlsError> {
        let mut anchors = Vec::new();
        for c in CertificateDer::pem_slice_iter(pem) {
            let c = c.map_err(|e| TlsError(format!("CA certificate: {e}")))?;
            let a = webpki::anchor_from_trusted_cert(&c)
                .map_err(|e| TlsError(format!("CA certificate: {e}")))?
                .to_owned();
            anchors.push(a);
        }
        if anchors.is_empty() {
            return Err(TlsError("no CA certificate in the file".into()));
        }
        Ok(Trust::Ca(Arc::new(anchors)))
    }

    /// May an announcement with this fingerprint lead to a link? (With a CA, only the
    /// handshake can tell; with fingerprints, an unpinned one is never tried.)
    pub fn may_accept(&self, fp: &Fingerprint) -> bool {
        match self {
            Trust::Fingerprints(v) => v.contains(fp),
            Trust::Ca(_) | Trust::AnyCertificate => true,
        }
    }
}

/// The ring provider, as the REST link uses it. rustls marks ring's default provider
/// deprecated because ring has no post-quantum key exchange; aws-lc-rs, which has, does not
/// build for the windows-gnu targets without cmake and nasm.
fn provider() -> Arc<CryptoProvider> {
    #[allow(deprecated)]
    Arc::new(rustls::crypto::ring::default_provider())
}

/// Checks a peer's certificate against a [`Trust`], for one usage.
#[derive(Debug)]
struct PinVerifier {
    trust: Trust,
    server: bool,
    algs: WebPkiSupportedAlgorithms,
}

fn webpki_error(e: webpki::Error) -> Error {
    use webpki::Error as W;
    Error::InvalidCertificate(match e {
        W::CertExpired { .. } => CertificateError::Expired,
        W::CertNotValidYet { .. } => CertificateError::NotValidYet,
        W::UnknownIssuer => CertificateError::UnknownIssuer,
        W::InvalidSignatureForPublicKey
        | W::UnsupportedSignatureAlgorithmContext(_)
        | W::UnsupportedSignatureAlgorithmForPublicKeyContext(_) => CertificateError::BadSignature,
        W::RequiredEkuNotFoundContext(_) => CertificateError::InvalidPurpose,
        _ => CertificateError::BadEncoding,
    })
}

impl PinVerifier {
    fn check(
        &self,
        end_entity: &CertificateDer<'_>,
        intermediates: &[CertificateDer<'_>],
        now: UnixTime,
    ) -> Result<(), Error> {
        let ee = webpki::EndEntityCert::try_from(end_entity).map_err(webpki_error)?;
        let own_anchor;
        let anchors: &[TrustAnchor<'_>] = match &self.trust {
            Trust::Fingerprints(pins) => {
                if !pins.contains(&fingerprint(end_entity)) {
                    return Err(Error::InvalidCertificate(
                        CertificateError::ApplicationVerificationFailure,
                    ));
                }
                own_anchor = [webpki::anchor_from_trusted_cert(end_entity).map_err(webpki_error)?];
                &own_anchor
            }
            Trust::AnyCertificate => {
                own_anchor = [webpki::anchor_from_trusted_cert(end_entity).map_err(webpki_error)?];
                &own_anchor
            }
            Trust::Ca(a) => a.as_slice(),
        };
        let self_anchored = !matches!(self.trust, Trust::Ca(_));
        let intermediates = if self_anchored { &[] } else { intermediates };
        let r = if self.server {
            ee.verify_for_usage(
                self.algs.all,
                anchors,
                intermediates,
                now,
                webpki::KeyUsage::server_auth(),
                None,
                None,
            )
        } else {
            ee.verify_for_usage(
                self.algs.all,
                anchors,
                intermediates,
                now,
                webpki::KeyUsage::client_auth(),
                None,
                None,
            )
        };
        r.map(drop).map_err(webpki_error)
    }
}

impl ServerCertVerifier for PinVerifier {
    fn verify_server_cert(
        &self,
        end_entity: &CertificateDer<'_>,
        intermediates: &[CertificateDer<'_>],
        _server_name: &ServerName<'_>,
        _ocsp_response: &[u8],
        now: UnixTime,
    ) -> Result<ServerCertVerified, Error> {
        self.check(end_entity, intermediates, now)?;
        Ok(ServerCertVerified::assertion())
    }

    fn verify_tls12_signature(
        &self,
        _message: &[u8],
        _cert: &CertificateDer<'_>,
        _dss: &DigitallySignedStruct,
    ) -> Result<HandshakeSignatureValid, Error> {
        // TLS 1.3 only: never called.
        Err(Error::PeerIncompatible(
            rustls::PeerIncompatible::Tls12NotOffered,
        ))
    }

    fn verify_tls13_signature(
        &self,
        message: &[u8],
        cert: &CertificateDer<'_>,
        dss: &DigitallySignedStruct,
    ) -> Result<HandshakeSignatureValid, Error> {
        rustls::crypto::verify_tls13_signature(message, cert, dss, &self.algs)
    }

    fn supported_verify_schemes(&self) -> Vec<SignatureScheme> {
        self.algs.supported_schemes()
    }
}

impl ClientCertVerifier for PinVerifier {
    fn root_hint_subjects(&self) -> &[DistinguishedName] {
        &[]
    }

    fn verify_client_cert(
        &self,
        end_entity: &CertificateDer<'_>,
        intermediates: &[CertificateDer<'_>],
        now: UnixTime,
    ) -> Result<ClientCertVerified, Error> {
        self.check(end_entity, intermediates, now)?;
        Ok(ClientCertVerified::assertion())
    }

    fn client_auth_mandatory(&self) -> bool {
        true
    }

    fn verify_tls12_signature(
        &self,
        _message: &[u8],
        _cert: &CertificateDer<'_>,
        _dss: &DigitallySignedStruct,
    ) -> Result<HandshakeSignatureValid, Error> {
        Err(Error::PeerIncompatible(
            rustls::PeerIncompatible::Tls12NotOffered,
        ))
    }

    fn verify_tls13_signature(
        &self,
        message: &[u8],
        cert: &CertificateDer<'_>,
        dss: &DigitallySignedStruct,
    ) -> Result<HandshakeSignatureValid, Error> {
        rustls::crypto::verify_tls13_signature(message, cert, dss, &self.algs)
    }

    fn supported_verify_schemes(&self) -> Vec<SignatureScheme> {
        self.algs.supported_schemes()
    }
}

/// The client side: own identity (presented to the server), the servers accepted.
pub fn client_config(
    identity: &Identity,
    trust: Trust,
) -> Result<Arc<rustls::ClientConfig>, TlsError> {
    if matches!(trust, Trust::AnyCertificate) {
        return Err(TlsError(
            "a client must pin its servers (fingerprints or a CA)".into(),
        ));
    }
    let provider = provider();
    let verifier = Arc::new(PinVerifier {
        trust,
        server: true,
        algs: provider.signature_verification_algorithms,
    });
    let c = rustls::ClientConfig::builder_with_provider(provider)
        .with_protocol_versions(TLS13_ONLY)
        .map_err(|e| TlsError(e.to_string()))?
        .dangerous()
        .with_custom_certificate_verifier(verifier)
        .with_client_auth_cert(identity.chain.clone(), identity.key.clone_key())
        .map_err(|e| TlsError(e.to_string()))?;
    Ok(Arc::new(c))
}

/// The server side: own identity, the clients accepted (a certificate is always required).
pub fn server_config(
    identity: &Identity,
    trust: Trust,
) -> Result<Arc<rustls::ServerConfig>, TlsError> {
    let provider = provider();
    let verifier = Arc::new(PinVerifier {
        trust,
        server: false,
        algs: provider.signature_verification_algorithms,
    });
    let c = rustls::ServerConfig::builder_with_provider(provider)
        .with_protocol_versions(TLS13_ONLY)
        .map_err(|e| TlsError(e.to_string()))?
        .with_client_cert_verifier(verifier)
        .with_single_cert(identity.chain.clone(), identity.key.clone_key())
        .map_err(|e| TlsError(e.to_string()))?;
    Ok(Arc::new(c))
}

/// The certificate a server presented to a [`recording_client_config`]'s handshake.
pub type Seen = Arc<std::sync::Mutex<Option<CertificateDer<'static>>>>;

/// A copy of a client configuration whose server check (the pins of `trust`, as
/// [`client_config`]'s) first records the certificate the server presents: a link
/// check (`opcdiag doctor`) can name the certificate of a server its pins refuse. The
/// verdict is the pins' own; nothing more is accepted.
pub fn recording_client_config(
    base: &rustls::ClientConfig,
    trust: Trust,
) -> (Arc<rustls::ClientConfig>, Seen) {
    let seen: Seen = Arc::default();
    let verifier = Arc::new(RecordingVerifier {
        inner: PinVerifier {
            trust,
            server: true,
            algs: provider().signature_verification_algorithms,
        },
        seen: seen.clone(),
    });
    let mut c = base.clone();
    c.dangerous().set_certificate_verifier(verifier);
    (Arc::new(c), seen)
}

#[derive(Debug)]
struct RecordingVerifier {
    inner: PinVerifier,
    seen: Seen,
}

impl ServerCertVerifier for RecordingVerifier {
    fn verify_server_cert(
        &self,
        end_entity: &CertificateDer<'_>,
        intermediates: &[CertificateDer<'_>],
        server_name: &ServerName<'_>,
        ocsp_response: &[u8],
        now: UnixTime,
    ) -> Result<ServerCertVerified, Error> {
        *self.seen.lock().unwrap_or_else(|p| p.into_inner()) =
            Some(end_entity.clone().into_owned());
        self.inner
            .verify_server_cert(end_entity, intermediates, server_name, ocsp_response, now)
    }

    fn verify_tls12_signature(
        &self,
        message: &[u8],
        cert: &CertificateDer<'_>,
        dss: &DigitallySignedStruct,
    ) -> Result<HandshakeSignatureValid, Error> {
        ServerCertVerifier::verify_tls12_signature(&self.inner, message, cert, dss)
    }

    fn verify_tls13_signature(
        &self,
        message: &[u8],
        cert: &CertificateDer<'_>,
        dss: &DigitallySignedStruct,
    ) -> Result<HandshakeSignatureValid, Error> {
        ServerCertVerifier::verify_tls13_signature(&self.inner, message, cert, dss)
    }

    fn supported_verify_schemes(&self) -> Vec<SignatureScheme> {
        ServerCertVerifier::supported_verify_schemes(&self.inner)
    }
}

/// The end of a certificate's validity (`notAfter`) in seconds since 1970 (UTC); `None`
/// when the DER does not hold one where X.509 puts it.
pub fn not_after(cert: &CertificateDer<'_>) -> Option<i64> {
    // One DER element at the start of `d`: (tag, contents, rest).
    fn element(d: &[u8]) -> Option<(u8, &[u8], &[u8])> {
        let (&tag, d) = d.split_first()?;
        let (&first, mut d) = d.split_first()?;
        let len = if first < 0x80 {
            usize::from(first)
        } else {
            let n = usize::from(first & 0x7F);
            if n == 0 || n > 4 || d.len() < n {
                return None;
            }
            let (bytes, rest) = d.split_at(n);
            d = rest;
            bytes.iter().fold(0usize, |a, b| (a << 8) | usize::from(*b))
        };
        (d.len() >= len).then(|| (tag, &d[..len], &d[len..]))
    }
    let (_, cert, _) = element(cert.as_ref())?;
    let (_, tbs, _) = element(cert)?;
    let mut rest = tbs;
    let (tag, _, r) = element(rest)?;
    if tag == 0xA0 {
        rest = r; // the explicit version
    }
    // serialNumber, signature, issuer, then validity.
    for _ in 0..3 {
        rest = element(rest)?.2;
    }
    let (_, validity, _) = element(rest)?;
    let (_, _, after) = element(validity)?;
    let (tag, time, _) = element(after)?;
    let text = std::str::from_utf8(time).ok()?;
    let digits = text.strip_suffix('Z')?;
    let (year, rest) = match tag {
        0x17 if digits.len() == 12 => {
            let yy: i64 = digits[..2].parse().ok()?;
            (if yy >= 50 { 1900 + yy } else { 2000 + yy }, &digits[2..])
        }
        0x18 if digits.len() == 14 => (digits[..4].parse().ok()?, &digits[4..]),
        _ => return None,
    };
    let field = |i: usize| -> Option<i64> { rest.get(i..i + 2)?.parse().ok() };
    let (month, day) = (field(0)?, field(2)?);
    let secs = field(4)? * 3600 + field(6)? * 60 + field(8)?;
    // Days from 1970-01-01 to the civil date (proleptic Gregorian).
    let (y, m) = if month <= 2 {
        (year - 1, month + 9)
    } else {
        (year, month - 3)
    };
    let era = y.div_euclid(400);
    let yoe = y - era * 400;
    let doy = (153 * m + 2) / 5 + day - 1;
    let doe = yoe * 365 + yoe / 4 - yoe / 100 + doy;
    Some((era * 146_097 + doe - 719_468) * 86_400 + secs)
}

/// The fingerprint of the peer's certificate after a handshake.
pub fn peer_fingerprint(conn: &rustls::CommonState) -> Option<Fingerprint> {
    conn.peer_certificates()
        .and_then(|c| c.first())
        .map(fingerprint)
}

/// The peer's identity after a handshake (`cert:<fingerprint>`).
pub fn peer_identity(conn: &rustls::CommonState) -> Option<String> {
    peer_fingerprint(conn).map(|f| identity_of(&f))
}

/// The server name the client sends.
pub fn sni() -> ServerName<'static> {
    #[allow(clippy::expect_used)]
    ServerName::try_from(SNI_NAME).expect("SNI_NAME is a valid DNS name")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fingerprints_parse_in_every_usual_spelling() {
        let fp: Fingerprint = std::array::from_fn(|i| i as u8 * 7);
        let hex = fingerprint_hex(&fp);
        assert_eq!(hex.len(), 64);
        let colons = fp
            .iter()
            .map(|b| format!("{b:02X}"))
            .collect::<Vec<_>>()
            .join(":");
        for s in [
            hex.clone(),
            hex.to_uppercase(),
            colons,
            format!("cert:{hex}"),
            format!(" sha256:{hex} "),
        ] {
            assert_eq!(parse_fingerprint(&s), Ok(fp), "{s}");
        }
        assert!(parse_fingerprint(&hex[..62]).is_err());
        assert!(parse_fingerprint(&format!("{}zz", &hex[..62])).is_err());
        assert_eq!(identity_of(&fp), format!("cert:{hex}"));
        assert_eq!(
            parse_fingerprints(&format!("{hex}, {hex},")).map(|v| v.len()),
            Ok(2)
        );
    }

    #[test]
    fn not_after_is_read_from_the_certificate() {
        // rcgen writes UTCTime up to 2049 and GeneralizedTime from 2050 (RFC 5280).
        for (to, unix) in [
            (2031, 1_924_992_000),
            (2001, 978_307_200),
            (2061, 2_871_763_200),
        ] {
            let g = generate("S1", Some((2000, to))).unwrap();
            assert_eq!(not_after(g.identity.certificate()), Some(unix), "{to}");
        }
        assert_eq!(
            not_after(&CertificateDer::from(vec![0x30, 0x03, 0x02, 0x01])),
            None
        );
    }

    #[test]
    fn generated_identity_round_trips_through_pem_and_mismatched_key_is_refused() {
        let a = generate("S1", None).unwrap();
        let b = generate("S2", None).unwrap();
        let again = Identity::from_pem(a.cert_pem.as_bytes(), a.key_pem.as_bytes()).unwrap();
        assert_eq!(again.fingerprint(), a.identity.fingerprint());
        assert_ne!(a.identity.fingerprint(), b.identity.fingerprint());
        let e = Identity::from_pem(a.cert_pem.as_bytes(), b.key_pem.as_bytes()).unwrap_err();
        assert!(e.0.contains("does not belong"), "{e}");
        assert!(Identity::from_pem(b"", a.key_pem.as_bytes()).is_err());
        // Debug never shows the key.
        assert!(!format!("{:?}", a.identity).contains("PRIVATE"));
    }

    #[test]
    fn pinned_certificates_are_checked_for_validity_and_pinning() {
        let good = generate("S1", None).unwrap();
        let expired = generate("S1", Some((2000, 2001))).unwrap();
        let now = UnixTime::now();
        let pins = Trust::Fingerprints(vec![
            good.identity.fingerprint(),
            expired.identity.fingerprint(),
        ]);
        let algs = provider().signature_verification_algorithms;
        for server in [true, false] {
            let v = PinVerifier {
                trust: pins.clone(),
                server,
                algs,
            };
            assert_eq!(v.check(good.identity.certificate(), &[], now), Ok(()));
            assert_eq!(
                v.check(expired.identity.certificate(), &[], now),
                Err(Error::InvalidCertificate(CertificateError::Expired))
            );
            let other = generate("S1", None).unwrap();
            assert_eq!(
                v.check(other.identity.certificate(), &[], now),
                Err(Error::InvalidCertificate(
                    CertificateError::ApplicationVerificationFailure
                ))
            );
        }
        // A CA file trusts what the CA signed, nothing else.
        let ca = Trust::ca_pem(good.cert_pem.as_bytes()).unwrap();
        let v = PinVerifier {
            trust: ca,
            server: true,
            algs,
        };
        assert_eq!(
            v.check(
                generate("X", None).unwrap().identity.certificate(),
                &[],
                now
            ),
            Err(Error::InvalidCertificate(CertificateError::UnknownIssuer))
        );
    }
}
