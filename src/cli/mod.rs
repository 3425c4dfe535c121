//! Command-line front end: argument types and the commands behind them.
