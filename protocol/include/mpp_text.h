/*
 * mpp_text.h - text that a person reads, made safe to print: what mpmd's
 * log and mpmctl show of names, errors and other text a client or the
 * server supplied.  A terminal acts on control characters (ESC sequences
 * recolour, retitle or move the cursor; an 8-bit CSI too), and a terminal
 * or an editor reorders text at the bidirectional controls (U+202E shows
 * "abc" as "cba") and breaks lines at U+2028/U+2029; a literal backslash
 * would make "\x1b" typed as text look like an escaped ESC.  One escape
 * for all of it, shared by the daemon and the clients.  Plain C.
 */
#ifndef MPP_TEXT_H
#define MPP_TEXT_H

#include <stddef.h>

/* Copies s into buf (n bytes, always NUL-terminated when n > 0) with
 *   \ as \\, newline, return and tab as \n \r \t, the other C0 controls
 *   and DEL as \xHH;
 *   the C1 controls U+0080..U+009F as \u00HH;
 *   the bidirectional controls U+061C, U+200E, U+200F, U+202A..U+202E,
 *   U+2066..U+2069 and the separators U+2028, U+2029 as \uHHHH;
 *   a byte that does not begin valid UTF-8 as \xHH;
 * everything else as it is.  An escape that does not fit is left out with
 * what follows (the text is cut short, never mid-escape).  NULL s is "".
 * Returns the length written. */
size_t mpp_text_escape(const char *s, char *buf, size_t n);

/* Room mpp_text_escape needs for n bytes of text, with the NUL. */
#define MPP_TEXT_ESC_LEN(n) (6 * (n) + 1)

#endif
