//! The stepper process: the IPC loop around the library (written by the lead; replaced at merge).
