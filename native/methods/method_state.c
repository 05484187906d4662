/* DeformKit: the saved state of a method that carries one (dk_method.h, dk_state_*). */
#include "dk_method.h"

#include <stdio.h>
#include <string.h>

static const char magic[8] = {'D', 'K', 'S', 'T', 'A', 'T', 'E', '1'};

static size_t spans_bytes(const dk_state_span *spans, int n_spans)
{
    size_t total = 0;
    for (int k = 0; k < n_spans; k++)
        total += spans[k].bytes;
    return total;
}

size_t dk_state_size(const dk_state_span *spans, int n_spans)
{
    return sizeof(dk_state_header) + spans_bytes(spans, n_spans);
}

static void make_header(const char *method, const uint64_t shape[4], size_t payload,
                        dk_state_header *h)
{
    memset(h, 0, sizeof *h);
    memcpy(h->magic, magic, sizeof magic);
    strncpy(h->method, method, sizeof h->method - 1);
    for (int k = 0; k < 4; k++)
        h->shape[k] = shape[k];
    h->payload = payload;
}

dk_status dk_state_save(const char *method, const uint64_t shape[4], const dk_state_span *spans,
                        int n_spans, void *state, size_t size, dk_error *err)
{
    const size_t want = dk_state_size(spans, n_spans);
    if (!state || size != want)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "%s save_state: the buffer must be state_size() = %zu bytes, not "
                            "%zu",
                            method, want, state ? size : (size_t)0);
    dk_state_header h;
    make_header(method, shape, want - sizeof h, &h);
    unsigned char *out = state;
    memcpy(out, &h, sizeof h);
    out += sizeof h;
    for (int k = 0; k < n_spans; k++) {
        if (spans[k].bytes)
            memcpy(out, spans[k].data, spans[k].bytes);
        out += spans[k].bytes;
    }
    return DK_OK;
}

dk_status dk_state_check(const char *method, const uint64_t shape[4],
                         const dk_state_span *spans, int n_spans, const void *state,
                         size_t size, dk_error *err)
{
    if (!state || size < sizeof(dk_state_header))
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "%s restore_state: %zu bytes are not a saved state (its header "
                            "alone is %zu)",
                            method, state ? size : (size_t)0, sizeof(dk_state_header));
    dk_state_header h, want;
    memcpy(&h, state, sizeof h);
    make_header(method, shape, spans_bytes(spans, n_spans), &want);
    if (memcmp(h.magic, magic, sizeof magic) != 0)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "%s restore_state: not a saved state (no DKSTATE1 header)", method);
    if (memcmp(h.method, want.method, sizeof h.method) != 0) {
        char other[sizeof h.method + 1];
        memcpy(other, h.method, sizeof h.method);
        other[sizeof h.method] = '\0';
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "%s restore_state: the state was saved by %s", method, other);
    }
    for (int k = 0; k < 4; k++)
        if (h.shape[k] != want.shape[k])
            return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                                "%s restore_state: the state was saved by an object bound "
                                "otherwise (its size %d is %llu, this object's %llu: another "
                                "mesh, constraints or options)",
                                method, k, (unsigned long long)h.shape[k],
                                (unsigned long long)want.shape[k]);
    if (h.payload != want.payload || size != sizeof h + want.payload)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "%s restore_state: %zu bytes, but this object's state is %zu "
                            "(truncated, or saved by another build)",
                            method, size, (size_t)(sizeof h + want.payload));
    return DK_OK;
}

void dk_state_restore_spans(const dk_state_span *spans, int n_spans, const void *state)
{
    const unsigned char *in = (const unsigned char *)state + sizeof(dk_state_header);
    for (int k = 0; k < n_spans; k++) {
        if (spans[k].bytes)
            memcpy(spans[k].data, in, spans[k].bytes);
        in += spans[k].bytes;
    }
}
