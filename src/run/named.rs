//! Enumerations that users name with a lower-case word: on the command line,
//! in case files, in statistics and in messages.
//!
//! [`named_enum!`](crate::named_enum) declares such an enumeration from one
//! list of variants and words, and derives everything that reads or writes
//! the words from that list: `name()`, `parse()` (with an error that lists
//! the accepted words), [`std::str::FromStr`], [`std::fmt::Display`] and
//! serde's `Serialize` and `Deserialize`. A new variant is then one line.

/// Declares a `Copy` enumeration whose variants have lower-case names.
///
/// ```text
/// crate::named_enum! {
///     /// A side of the surface.
///     pub enum Side: "side" {
///         /// Inside.
///         In = "in" | "inside",
///         /// Outside.
///         Out = "out",
///     }
/// }
/// assert_eq!("inside".parse::<Side>().unwrap(), Side::In);
/// assert_eq!(Side::Out.name(), "out");
/// assert_eq!(
///     Side::parse("up").unwrap_err().message(),
///     "unknown side 'up' (expected in or out)"
/// );
/// ```
///
/// The first word of a variant is its name; words after `|` are also
/// accepted when parsing. The string after the enum's name says what the
/// values are, for the message of an unknown word.
/// (Crate-internal: exported only so that every module can name it as
/// `crate::named_enum!`; the tests below run this example.)
#[doc(hidden)]
#[macro_export]
macro_rules! named_enum {
    (
        $(#[$meta:meta])*
        $vis:vis enum $ty:ident : $what:literal {
            $(
                $(#[$vmeta:meta])*
                $variant:ident = $name:literal $(| $alias:literal)*
            ),+ $(,)?
        }
    ) => {
        $(#[$meta])*
        #[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
        $vis enum $ty {
            $( $(#[$vmeta])* $variant, )+
        }

        impl $ty {
            /// Every value, in declaration order.
            pub const ALL: &'static [$ty] = &[$($ty::$variant),+];

            /// The lower-case name.
            pub fn name(self) -> &'static str {
                match self {
                    $($ty::$variant => $name,)+
                }
            }

            /// Parses a name (or an accepted alias).
            pub fn parse(s: &str) -> $crate::Result<$ty> {
                match s {
                    $($name $(| $alias)* => Ok($ty::$variant),)+
                    _ => Err($crate::Error::invalid(format!(
                        "unknown {} '{}' (expected {})",
                        $what,
                        s,
                        $crate::run::named::one_of(&[$($name),+])
                    ))),
                }
            }
        }

        impl ::std::str::FromStr for $ty {
            type Err = $crate::Error;
            fn from_str(s: &str) -> $crate::Result<$ty> {
                $ty::parse(s)
            }
        }

        impl ::std::fmt::Display for $ty {
            fn fmt(&self, f: &mut ::std::fmt::Formatter<'_>) -> ::std::fmt::Result {
                f.write_str(self.name())
            }
        }

        impl ::serde::Serialize for $ty {
            fn serialize<S: ::serde::Serializer>(&self, s: S) -> ::std::result::Result<S::Ok, S::Error> {
                s.serialize_str(self.name())
            }
        }

        impl<'de> ::serde::Deserialize<'de> for $ty {
            fn deserialize<D: ::serde::Deserializer<'de>>(d: D) -> ::std::result::Result<$ty, D::Error> {
                let s = <::std::borrow::Cow<'de, str> as ::serde::Deserialize>::deserialize(d)?;
                $ty::parse(&s).map_err(|e| <D::Error as ::serde::de::Error>::custom(e.message()))
            }
        }
    };
}

/// `a, b or c`, for messages that list the accepted words.
pub fn one_of(names: &[&str]) -> String {
    match names {
        [] => String::new(),
        [one] => (*one).to_string(),
        [init @ .., last] => format!("{} or {last}", init.join(", ")),
    }
}

#[cfg(test)]
mod tests {
    crate::named_enum! {
        /// A test enumeration.
        enum Shape: "shape" {
            /// Round.
            Ball = "ball" | "sphere",
            /// Square.
            Cube = "cube",
            /// Pointy.
            Cone = "cone",
        }
    }

    #[test]
    fn names_parse_and_round_trip() {
        for &s in Shape::ALL {
            assert_eq!(Shape::parse(s.name()).unwrap(), s);
            assert_eq!(s.to_string(), s.name());
            let json = serde_json::to_string(&s).unwrap();
            assert_eq!(serde_json::from_str::<Shape>(&json).unwrap(), s);
        }
        assert_eq!("sphere".parse::<Shape>().unwrap(), Shape::Ball);
        let e = Shape::parse("pyramid").unwrap_err();
        assert_eq!(
            e.message(),
            "unknown shape 'pyramid' (expected ball, cube or cone)"
        );
        let e = serde_json::from_str::<Shape>("\"Ball\"").unwrap_err();
        assert!(e.to_string().contains("unknown shape 'Ball'"), "{e}");
    }
}
