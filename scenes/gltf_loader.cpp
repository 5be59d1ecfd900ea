// Placeholder until this file is written; see the header beside it.
