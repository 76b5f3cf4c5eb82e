/*
 * mpp_text.c - the escape of text shown to a person (see mpp_text.h): one
 * pass over the bytes, decoding UTF-8 only as far as needed to tell the
 * characters to escape (C1 controls, bidirectional controls, line and
 * paragraph separators) and the bytes that begin no valid sequence.
 * Guarded by daemon_names_escape (tests/daemon/t_daemon_bind.c), the name tests
 * there (daemon_names_*) and daemon_case_names.
 */
#include "mpp_text.h"

#include <string.h>

/* The length of the valid UTF-8 sequence at p (1..4), its code point in
 * *cp; 0 if p does not begin one (overlong forms, surrogates and code
 * points above U+10FFFF are not valid). */
static size_t utf8_seq(const unsigned char *p, unsigned long *cp)
{
    unsigned c = p[0];
    size_t len;
    unsigned long v, min;
    if (c < 0x80) {
        *cp = c;
        return 1;
    }
    if (c >= 0xc2 && c <= 0xdf)
        len = 2, v = c & 0x1f, min = 0x80;
    else if (c >= 0xe0 && c <= 0xef)
        len = 3, v = c & 0x0f, min = 0x800;
    else if (c >= 0xf0 && c <= 0xf4)
        len = 4, v = c & 0x07, min = 0x10000;
    else
        return 0;
    for (size_t i = 1; i < len; i++) {
        if ((p[i] & 0xc0) != 0x80) return 0; /* also stops at the NUL */
        v = v << 6 | (p[i] & 0x3f);
    }
    if (v < min || v > 0x10ffff || (v >= 0xd800 && v <= 0xdfff)) return 0;
    *cp = v;
    return len;
}

/* 1 for the characters shown as \uHHHH: C1 controls, bidirectional
 * controls, line and paragraph separators. */
static int escaped_char(unsigned long cp)
{
    return (cp >= 0x80 && cp <= 0x9f) || cp == 0x61c || cp == 0x200e || cp == 0x200f ||
           (cp >= 0x2028 && cp <= 0x202e) || (cp >= 0x2066 && cp <= 0x2069);
}

size_t mpp_text_escape(const char *s, char *buf, size_t n)
{
    static const char hex[] = "0123456789abcdef";
    size_t k = 0;
    if (!n) return 0;
    for (const unsigned char *p = (const unsigned char *)(s ? s : ""); *p;) {
        char e[8];
        size_t el = 0;
        unsigned long cp = 0;
        size_t len = utf8_seq(p, &cp);
        if (len == 1 && cp >= 0x20 && cp != 0x7f && cp != '\\') {
            e[el++] = (char)cp;
        } else if (len == 1) {
            e[el++] = '\\';
            if (cp == '\\' || cp == '\n' || cp == '\r' || cp == '\t') {
                e[el++] = cp == '\\' ? '\\' : cp == '\n' ? 'n' : cp == '\r' ? 'r' : 't';
            } else {
                e[el++] = 'x';
                e[el++] = hex[cp >> 4];
                e[el++] = hex[cp & 15];
            }
        } else if (len == 0) {
            len = 1; /* a byte that begins no valid sequence */
            e[el++] = '\\';
            e[el++] = 'x';
            e[el++] = hex[p[0] >> 4];
            e[el++] = hex[p[0] & 15];
        } else if (escaped_char(cp)) {
            e[el++] = '\\';
            e[el++] = 'u';
            for (int sh = 12; sh >= 0; sh -= 4) e[el++] = hex[(cp >> sh) & 15];
        } else {
            memcpy(e, p, len);
            el = len;
        }
        if (k + el >= n) break;
        memcpy(buf + k, e, el);
        k += el;
        p += len;
    }
    buf[k] = 0;
    return k;
}
