//! Writing glTF.
