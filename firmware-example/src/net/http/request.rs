//! A request's head, read with `httparse` from the socket's receive buffer
//! in place (a connection carries one request, so its head starts at the
//! buffer's start), and what this server takes from it: the route, the
//! body's length and type, whether a form comes from this page (its
//! `Origin`, else its `Referer`, against its `Host`), and a password given
//! by HTTP basic authentication.

use heapless::Vec;

use crate::config::wire::PASSWORD_MAX;

/// Headers read at most (a browser sends about 15).
pub const HEADERS: usize = 24;

/// What a request asks for.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Route {
    /// `GET /`: the status page.
    Status,
    /// `GET /live`: the status page's live part (what its script fetches).
    Live,
    /// `GET /config`: the configuration form.
    Config,
    /// `GET /frames.txt`: the last frames, to download.
    Frames,
    /// `POST /config`: a change.
    SaveConfig,
    /// `POST /restart`: a restart.
    Restart,
    /// A path this server does not have.
    NotFound,
    /// A method other than GET and POST (or GET where only POST goes).
    BadMethod,
}

impl Route {
    /// Whether it writes (a form with the password).
    pub const fn writes(self) -> bool {
        matches!(self, Route::SaveConfig | Route::Restart)
    }
}

/// Where a form comes from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Origin {
    /// This gateway's own page (`Origin`, else `Referer`, names its `Host`).
    Same,
    /// Another page (or `Origin: null`).
    Other,
    /// Neither header (a program, not a browser).
    Absent,
}

/// What a request's head says.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Head {
    /// What it asks for.
    pub route: Route,
    /// Bytes of the head, up to the blank line.
    pub len: usize,
    /// `Content-Length`.
    pub content_length: Option<u32>,
    /// The body is `application/x-www-form-urlencoded`.
    pub form: bool,
    /// Where it comes from.
    pub origin: Origin,
    /// The password of a basic authentication (its user name ignored).
    pub password: Option<Vec<u8, PASSWORD_MAX>>,
}

/// What the bytes received so far hold.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Parsed {
    /// Not the whole head yet.
    Partial,
    /// The head.
    Head(Head),
    /// Not a request this server takes: the reason.
    Bad(&'static str),
}

/// Reads a request's head from `buf`.
pub fn parse(buf: &[u8]) -> Parsed {
    let mut headers = [httparse::EMPTY_HEADER; HEADERS];
    let mut req = httparse::Request::new(&mut headers);
    let len = match req.parse(buf) {
        Ok(httparse::Status::Complete(n)) => n,
        Ok(httparse::Status::Partial) => return Parsed::Partial,
        Err(httparse::Error::TooManyHeaders) => return Parsed::Bad("too many header lines"),
        Err(_) => return Parsed::Bad("not an HTTP/1.x request"),
    };
    let path = req.path.unwrap_or("");
    let path = path.split('?').next().unwrap_or(path);
    let route = match (req.method.unwrap_or(""), path) {
        ("GET", "/") => Route::Status,
        ("GET", "/live") => Route::Live,
        ("GET", "/config") => Route::Config,
        ("GET", "/frames.txt") => Route::Frames,
        ("POST", "/config") => Route::SaveConfig,
        ("POST", "/restart") => Route::Restart,
        ("GET", _) => Route::NotFound,
        _ => Route::BadMethod,
    };
    let header = |name: &str| {
        req.headers
            .iter()
            .find(|h| h.name.eq_ignore_ascii_case(name))
            .map(|h| h.value)
    };
    let content_length = match header("content-length") {
        None => None,
        Some(v) => match crate::text::parse_dec(v.trim_ascii()) {
            Some(n) => Some(n),
            None => return Parsed::Bad("a Content-Length that is not a number"),
        },
    };
    let form = header("content-type").is_some_and(|v| {
        let v = v.split(|&b| b == b';').next().unwrap_or(v);
        v.trim_ascii()
            .eq_ignore_ascii_case(b"application/x-www-form-urlencoded")
    });
    let Some(host) = header("host") else {
        return Parsed::Bad("no Host header");
    };
    let origin = match (header("origin"), header("referer")) {
        (Some(o), _) => same_origin(o, host, false),
        (None, Some(r)) => same_origin(r, host, true),
        (None, None) => Origin::Absent,
    };
    let password = header("authorization").and_then(basic_password);
    Parsed::Head(Head {
        route,
        len,
        content_length,
        form,
        origin,
        password,
    })
}

/// Whether `url` is `http://HOST` (an `Origin`), or `http://HOST/...` (a
/// `Referer`).
fn same_origin(url: &[u8], host: &[u8], referer: bool) -> Origin {
    let Some(rest) = url
        .get(..7)
        .filter(|s| s.eq_ignore_ascii_case(b"http://"))
        .and_then(|_| url.get(7..))
    else {
        return Origin::Other;
    };
    let slash = rest.iter().position(|&b| b == b'/');
    let authority = rest.get(..slash.unwrap_or(rest.len())).unwrap_or(&[]);
    if authority.eq_ignore_ascii_case(host.trim_ascii()) && slash.is_some() == referer {
        Origin::Same
    } else {
        Origin::Other
    }
}

/// The password of `Basic BASE64(user:password)`.
fn basic_password(value: &[u8]) -> Option<Vec<u8, PASSWORD_MAX>> {
    let v = value.trim_ascii();
    let b64 = v
        .get(..6)
        .filter(|s| s.eq_ignore_ascii_case(b"basic "))
        .and_then(|_| v.get(6..))?
        .trim_ascii();
    let mut decoded: Vec<u8, { PASSWORD_MAX + 64 }> = Vec::new();
    base64(b64, &mut decoded)?;
    let colon = decoded.iter().position(|&b| b == b':')?;
    Vec::from_slice(decoded.get(colon + 1..)?).ok()
}

/// Standard base64 (with `=` padding) into `out`; `None` if malformed or
/// too long.
fn base64<const N: usize>(s: &[u8], out: &mut Vec<u8, N>) -> Option<()> {
    let value = |c: u8| -> Option<u32> {
        Some(match c {
            b'A'..=b'Z' => c - b'A',
            b'a'..=b'z' => c - b'a' + 26,
            b'0'..=b'9' => c - b'0' + 52,
            b'+' => 62,
            b'/' => 63,
            _ => return None,
        } as u32)
    };
    if !s.len().is_multiple_of(4) {
        return None;
    }
    for quad in s.chunks(4) {
        let pad = quad.iter().rev().take_while(|&&c| c == b'=').count();
        if pad > 2 {
            return None;
        }
        let mut n = 0u32;
        for (i, &c) in quad.iter().enumerate() {
            let d = if i >= 4 - pad { 0 } else { value(c)? };
            n = n << 6 | d;
        }
        let bytes = n.to_be_bytes();
        for &b in bytes.get(1..4 - pad)? {
            out.push(b).ok()?;
        }
    }
    Some(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// What Chromium sends when the configuration form is submitted.
    const CHROMIUM_POST: &[u8] = b"POST /config HTTP/1.1\r\n\
        Host: 127.0.0.1:38080\r\n\
        Connection: keep-alive\r\n\
        Content-Length: 44\r\n\
        Cache-Control: max-age=0\r\n\
        Origin: http://127.0.0.1:38080\r\n\
        Content-Type: application/x-www-form-urlencoded\r\n\
        Upgrade-Insecure-Requests: 1\r\n\
        User-Agent: Mozilla/5.0 (X11; Linux x86_64) AppleWebKit/537.36 (KHTML, like Gecko) HeadlessChrome/120.0.0.0 Safari/537.36\r\n\
        Accept: text/html,application/xhtml+xml,application/xml;q=0.9,image/avif,image/webp,*/*;q=0.8\r\n\
        Sec-Fetch-Site: same-origin\r\n\
        Sec-Fetch-Mode: navigate\r\n\
        Sec-Fetch-User: ?1\r\n\
        Sec-Fetch-Dest: document\r\n\
        Referer: http://127.0.0.1:38080/config\r\n\
        Accept-Encoding: gzip, deflate, br\r\n\
        Accept-Language: en-US,en;q=0.9\r\n\r\n\
        modbus.unit=5&password=plant-1234&x=1234567";

    #[test]
    fn a_browser_s_form_post() {
        let Parsed::Head(h) = parse(CHROMIUM_POST) else {
            panic!("{:?}", parse(CHROMIUM_POST));
        };
        assert_eq!(h.route, Route::SaveConfig);
        assert_eq!(h.content_length, Some(44));
        assert!(h.form);
        assert_eq!(h.origin, Origin::Same);
        assert_eq!(&CHROMIUM_POST[h.len..h.len + 11], b"modbus.unit");
        // Cut anywhere in its head, it is partial.
        for n in [0, 10, 200, h.len - 1] {
            assert_eq!(parse(&CHROMIUM_POST[..n]), Parsed::Partial, "{n}");
        }
    }

    #[test]
    fn a_form_from_another_page_is_told_apart() {
        let post = |origin: &str| {
            let req = std::format!("POST /restart HTTP/1.1\r\nHost: 10.0.2.15\r\n{origin}\r\n\r\n");
            match parse(req.as_bytes()) {
                Parsed::Head(h) => h.origin,
                other => panic!("{other:?}"),
            }
        };
        extern crate std;
        assert_eq!(post("Origin: http://10.0.2.15"), Origin::Same);
        assert_eq!(post("Origin: http://evil.example"), Origin::Other);
        assert_eq!(post("Origin: http://10.0.2.15.evil.example"), Origin::Other);
        assert_eq!(post("Origin: null"), Origin::Other);
        assert_eq!(post("Origin: https://10.0.2.15"), Origin::Other);
        assert_eq!(post("Referer: http://10.0.2.15/config"), Origin::Same);
        assert_eq!(post("Referer: http://10.0.2.150/config"), Origin::Other);
        assert_eq!(post("X-Nothing: 1"), Origin::Absent);
    }

    #[test]
    fn routes_and_refusals() {
        let route = |r: &[u8]| match parse(r) {
            Parsed::Head(h) => h.route,
            other => panic!("{other:?}"),
        };
        assert_eq!(
            route(b"GET /?x=1 HTTP/1.1\r\nHost: a\r\n\r\n"),
            Route::Status
        );
        assert_eq!(route(b"GET /live HTTP/1.1\r\nHost: a\r\n\r\n"), Route::Live);
        assert_eq!(
            route(b"GET /nope HTTP/1.1\r\nHost: a\r\n\r\n"),
            Route::NotFound
        );
        assert_eq!(
            route(b"DELETE / HTTP/1.1\r\nHost: a\r\n\r\n"),
            Route::BadMethod
        );
        assert_eq!(
            route(b"POST / HTTP/1.1\r\nHost: a\r\n\r\n"),
            Route::BadMethod
        );
        assert_eq!(
            parse(b"GET / HTTP/1.1\r\n\r\n"),
            Parsed::Bad("no Host header")
        );
        assert_eq!(
            parse(b"\x16\x03\x01\x02\x00"),
            Parsed::Bad("not an HTTP/1.x request")
        );
        assert_eq!(
            parse(b"POST /config HTTP/1.1\r\nHost: a\r\nContent-Length: -1\r\n\r\n"),
            Parsed::Bad("a Content-Length that is not a number")
        );
    }

    #[test]
    fn basic_authentication_gives_the_password() {
        // `gateway:plant 1234`, as a browser's login dialog sends it.
        let r =
            b"GET / HTTP/1.1\r\nHost: a\r\nAuthorization: Basic Z2F0ZXdheTpwbGFudCAxMjM0\r\n\r\n";
        let Parsed::Head(h) = parse(r) else { panic!() };
        assert_eq!(h.password.as_deref(), Some(&b"plant 1234"[..]));
        assert_eq!(basic_password(b"Basic !!!!"), None);
        assert_eq!(basic_password(b"Bearer abc"), None);
        // `:x` and `a:` (padded twice and once).
        assert_eq!(basic_password(b"Basic Ong=").as_deref(), Some(&b"x"[..]));
        assert_eq!(basic_password(b"Basic YTo=").as_deref(), Some(&b""[..]));
    }
}
