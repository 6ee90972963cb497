//! `record!`: a store record struct and its `sqlx::FromRow` (each field
//! read from the column of its name), for either backend.
//!
//! sqlx's `FromRow` derive comes with its macros crate, which compiles the
//! SQLite and PostgreSQL drivers a second time for the compiler's host
//! (the bundled SQLite's C source among them) although no query is checked
//! at compile time here; this macro_rules replaces it (BENCHMARKS.md has
//! what it saved).

/// A `pub struct` with `pub` fields, and its `FromRow` for any row type
/// whose database decodes every field's type.
macro_rules! record {
    (
        $(#[$meta:meta])*
        pub struct $name:ident {
            $(
                $(#[$field_meta:meta])*
                pub $field:ident : $ty:ty,
            )*
        }
    ) => {
        $(#[$meta])*
        pub struct $name {
            $(
                $(#[$field_meta])*
                pub $field: $ty,
            )*
        }

        impl<'r, R: sqlx::Row> sqlx::FromRow<'r, R> for $name
        where
            &'static str: sqlx::ColumnIndex<R>,
            $($ty: sqlx::Decode<'r, R::Database> + sqlx::Type<R::Database>,)*
        {
            fn from_row(row: &'r R) -> sqlx::Result<Self> {
                Ok($name {
                    $($field: row.try_get(stringify!($field))?,)*
                })
            }
        }
    };
}

pub(super) use record;
