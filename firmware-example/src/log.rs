//! Logging: `defmt` over semihosting with the `defmt` feature, nothing
//! without it (the arguments are still type-checked, never evaluated).
//!
//! Use `{}` placeholders or defmt's typed ones (`{=u16}`); both work in
//! either build.

#[cfg(feature = "defmt")]
macro_rules! info {
    ($($t:tt)*) => { defmt::info!($($t)*) };
}
#[cfg(feature = "defmt")]
macro_rules! warning {
    ($($t:tt)*) => { defmt::warn!($($t)*) };
}

#[cfg(not(feature = "defmt"))]
macro_rules! info {
    ($fmt:literal $(, $arg:expr)* $(,)?) => {{
        if false {
            $( let _ = &$arg; )*
        }
    }};
}
#[cfg(not(feature = "defmt"))]
macro_rules! warning {
    ($fmt:literal $(, $arg:expr)* $(,)?) => {{
        if false {
            $( let _ = &$arg; )*
        }
    }};
}

pub(crate) use {info, warning};
