//! Closed sets of values a user picks by name — on the command line, in scene files — declared
//! once with [`choice!`](crate::choice!): the enum, each value's name and its one-line description (the
//! variant's doc comment), so library types carry no command-line framework and the CLI lists
//! the same words the library parses.

/// A closed set of named values ([`choice!`](crate::choice!) implements it).
pub trait Choice: Copy + Send + Sync + 'static {
    /// Every value, in the order help lists them.
    const ALL: &'static [Self];

    /// The value's name, as written on the command line and in files.
    fn name(self) -> &'static str;

    /// What the value means: its doc comment.
    fn help(self) -> &'static str;

    /// The value called `name`, if any.
    fn named(name: &str) -> Option<Self> {
        Self::ALL.iter().copied().find(|v| v.name() == name)
    }
}

/// Declare an enum whose variants are [`Choice`]s: each variant is written `Variant = "name"`
/// after its doc comment, which becomes its [`Choice::help`].
#[macro_export]
macro_rules! choice {
    (
        $(#[$meta:meta])*
        $vis:vis enum $name:ident {
            $( $(#[doc = $doc:literal])+ $variant:ident = $text:literal, )+
        }
    ) => {
        $(#[$meta])*
        $vis enum $name {
            $( $(#[doc = $doc])+ $variant, )+
        }

        impl $crate::choice::Choice for $name {
            const ALL: &'static [Self] = &[$($name::$variant),+];

            fn name(self) -> &'static str {
                match self {
                    $($name::$variant => $text),+
                }
            }

            fn help(self) -> &'static str {
                match self {
                    $($name::$variant => concat!($($doc),+).trim_ascii()),+
                }
            }
        }
    };
}

#[cfg(test)]
mod tests {
    use super::Choice;

    crate::choice! {
        /// A test set.
        #[derive(Debug, Clone, Copy, PartialEq, Eq)]
        enum Fruit {
            /// Red or green.
            Apple = "apple",
            /// Long and
            /// yellow.
            Banana = "banana",
        }
    }

    #[test]
    fn names_and_help_come_from_the_declaration() {
        assert_eq!(Fruit::ALL, &[Fruit::Apple, Fruit::Banana]);
        assert_eq!(Fruit::named("banana"), Some(Fruit::Banana));
        assert_eq!(Fruit::named("Banana"), None);
        assert_eq!(Fruit::Apple.name(), "apple");
        assert_eq!(Fruit::Apple.help(), "Red or green.");
        assert_eq!(Fruit::Banana.help(), "Long and yellow.");
    }
}
