//! The library half of the `fastrack` command-line tool: the load generator, which the serving benchmark
//! drives too. The subcommands themselves live in the binary (`src/commands/`, one file each).

#![warn(missing_docs)]

pub mod load_generator;
