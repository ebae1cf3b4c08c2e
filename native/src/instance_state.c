/* The instance core's FMU state (see instance.c): fmi2GetFMUstate / fmi3GetFMUState and the
 * rest, and the serialized format both FMI versions share. A state handed out carries a tag that
 * says whose it is, so that a foreign or freed pointer given back is refused; a serialized state
 * is a fixed 64-byte header with a CRC-32, then the Snapshot, checked field by field before the
 * instance takes it (check_snapshot, check_finite, the model's model_check_state).
 */
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmi2Functions.h"
#include "glue.h"
#include "guid.h" /* MODEL_GUID, written by the build */
#include "instance.h"

#define STATE_MAGIC 0x494d5053u    /* "IMPS" */

/* What fmi2GetFMUstate hands out: a Snapshot behind a tag that says whose it is, so that a
 * foreign or freed pointer given back to fmi2SetFMUstate / fmi2FreeFMUstate is refused. */
typedef struct {
    unsigned magic; /* STATE_MAGIC while allocated; fmi2FreeFMUstate clears it */
    unsigned n_vars;
    char identifier[32];
    Snapshot s;
} StateBox;

/* A serialized FMU state (format 2): this header, then the Snapshot's bytes. The header has the
 * same layout on every platform (fixed-width fields, 64 bytes); the checksum (CRC-32, the one of
 * zlib and of the Python FMUs' states) covers the header before it and the whole body, so a state
 * that is not one this FMU wrote (bytes flipped, cut, added, or another build's) is refused before
 * any of it is read. A body that passes the checksum is still checked field by field
 * (check_snapshot, check_finite): a checksum is no proof of origin, anyone can recompute it. */
#define SERIAL_MAGIC "IMPCNAT2"         /* native state, format 2 */
#define SERIAL_MAGIC_FORMAT1 0x494d5043u /* format 1 (no checksum): the first 4 bytes, "CPMI" */
#define SERIAL_GUID_MAX 40
typedef struct {
    char magic[8];                /* SERIAL_MAGIC */
    uint32_t n_vars;              /* N_VARS */
    uint32_t body_size;           /* sizeof(Snapshot) */
    char guid[SERIAL_GUID_MAX];   /* MODEL_GUID of the build that wrote it, NUL-padded */
    uint32_t flags;               /* 0 */
    uint32_t crc;                 /* CRC-32 of the 60 bytes above and of the body */
} SerialHeader;
typedef char serial_header_is_64_bytes[sizeof(SerialHeader) == 64 ? 1 : -1];
typedef char guid_fits_the_header[sizeof MODEL_GUID <= SERIAL_GUID_MAX ? 1 : -1];

/* --- FMU state -------------------------------------------------------------------------------- */

/* A state from outside (fmi2DeSerializeFMUstate, or memory the host may have overwritten) before
 * it becomes the instance's: every field the glue or the model reads is in range. Parameters
 * pass the same checks as when they are set, inputs are finite, Booleans 0 or 1, strings
 * NUL-terminated within STRING_MAX, times finite; the model's own state (counters, indices,
 * enumerations) is checked by model_check_state once initialization has built it. */
static int check_snapshot(const Snapshot *s, fmi2Type type, char *msg)
{
    const unsigned phase = (unsigned)s->phase;
    const int me_phase = s->phase == S_EVENT_MODE || s->phase == S_CONTINUOUS_TIME;
    int built;
    if (phase > (unsigned)S_TERMINATED) {
        return fail(msg, "phase %u is not a phase of the FMI state machine", phase);
    }
    if (me_phase != (type == fmi2ModelExchange) && s->phase != S_INSTANTIATED &&
        s->phase != S_INITIALIZATION && s->phase != S_TERMINATED) {
        return fail(msg, "phase %u belongs to the other interface (co-simulation / Model "
                         "Exchange) than this instance's", phase);
    }
    if (s->me_time_set != 0 && s->me_time_set != 1) {
        return fail(msg, "flag 'me_time_set' is %d, not 0 or 1", s->me_time_set);
    }
    if (!isfinite(s->me_time) || s->event_switches < 0 || s->event_switches > 1000) {
        return fail(msg, "Model Exchange time not finite or event counter out of range");
    }
    if (s->dirty != 0 && s->dirty != 1) {
        return fail(msg, "flag 'dirty' is %d, not 0 or 1", s->dirty);
    }
    if (!isfinite(s->last_time) || !isfinite(s->d.start_time)) {
        return fail(msg, "a time is not finite");
    }
    for (int vr = 0; vr < N_VARS; vr++) {
        const VarInfo *v = &VARS[vr];
        if (v->type == T_STRING) {
            if (!memchr(s->d.s[vr], '\0', STRING_MAX)) {
                return fail(msg, "string %s is not NUL-terminated within %d bytes", v->name,
                            STRING_MAX);
            }
            continue;
        }
        if (v->type == T_BOOLEAN && s->d.i[vr] != 0 && s->d.i[vr] != 1) {
            return fail(msg, "Boolean %s is %d, not 0 or 1", v->name, s->d.i[vr]);
        }
        if (v->causality == C_PARAMETER &&
            check_parameter(vr, v->type == T_REAL ? s->d.r[vr] : s->d.i[vr], msg)) {
            return 1;
        }
        if (v->causality == C_INPUT && v->type == T_REAL && !isfinite(s->d.r[vr])) {
            return fail(msg, "input %s is not finite (%g)", v->name, s->d.r[vr]);
        }
    }
    built = s->phase >= S_STEP_COMPLETE || (s->phase == S_INITIALIZATION && !s->dirty);
    /* (under Model Exchange, states and inputs may change the outputs after initialization:
     * dirty is then legitimately 1 in event or continuous-time mode, with the model built) */
    /* (tunable parameters may have changed since initialization: their model-level checks) */
    return built ? model_check_tunable(&s->d, msg) || model_check_state(&s->d, msg) : 0;
}

/* A pointer from fmi2GetFMUstate / fmi2DeSerializeFMUstate of this FMU, not yet freed (as far
 * as can be told: the same limits as instance_ok). */
static int state_ok(Instance *inst, const StateBox *box)
{
    if (box->magic != STATE_MAGIC || box->n_vars != N_VARS ||
        strncmp(box->identifier, MODEL_IDENTIFIER_STR, sizeof box->identifier) != 0) {
        log_message(inst, fmi2Error, "logStatusError",
                    "%s: the FMU state is not a live state of this %s FMU (freed, foreign or "
                    "overwritten): refused", inst->fn, MODEL_IDENTIFIER_STR);
        return 0;
    }
    return 1;
}

/* *state itself when it is a live state, a new one when it is NULL, else NULL (logged). */
static StateBox *state_for_writing(Instance *inst, fmi2FMUstate *state)
{
    StateBox *box = (StateBox *)*state;
    if (box) {
        return state_ok(inst, box) ? box : NULL;
    }
    box = (StateBox *)calloc(1, sizeof(StateBox));
    if (!box) {
        log_message(inst, fmi2Error, "logStatusError", "out of memory for an FMU state");
        return NULL;
    }
    box->magic = STATE_MAGIC;
    box->n_vars = N_VARS;
    strncpy(box->identifier, MODEL_IDENTIFIER_STR, sizeof box->identifier - 1);
    *state = box;
    return box;
}

fmi2Status instance_get_state(fmi2Component c, fmi2FMUstate *state)
{
    Instance *inst = (Instance *)c;
    StateBox *box;
    if (!state) {
        return ERROR_FN(inst, "the state pointer is NULL");
    }
    box = state_for_writing(inst, state);
    if (!box) {
        return fmi2Error;
    }
    box->s = inst->s;
    return fmi2OK;
}

fmi2Status instance_set_state(fmi2Component c, fmi2FMUstate state)
{
    Instance *inst = (Instance *)c;
    const StateBox *box = (const StateBox *)state;
    if (!box) {
        return ERROR_FN(inst, "the state is NULL");
    }
    if (!state_ok(inst, box)) {
        return fmi2Error;
    }
    if (check_snapshot(&box->s, inst->type, inst->msg)) {
        return ERROR_FN(inst, "invalid FMU state (%s): refused", inst->msg);
    }
    inst->s = box->s;
    return fmi2OK;
}

fmi2Status instance_free_state(fmi2Component c, fmi2FMUstate *state)
{
    Instance *inst = (Instance *)c;
    StateBox *box;
    if (!state || !*state) {
        return fmi2OK; /* FMI 2.0: a NULL state is ignored */
    }
    box = (StateBox *)*state;
    if (!state_ok(inst, box)) {
        return fmi2Error; /* freeing it could corrupt the host's heap */
    }
    *(volatile unsigned *)&box->magic = 0; /* volatile: see fmi2FreeInstance */
    free(box);
    *state = NULL;
    return fmi2OK;
}

/* CRC-32 (IEEE 802.3, reflected, as zlib's crc32) of n bytes, continuing from crc (0 to start).
 * Bitwise and branch-free: states are a few kilobytes, serialized rarely. */
uint32_t crc32_update(uint32_t crc, const unsigned char *p, size_t n)
{
    crc = ~crc;
    while (n--) {
        crc ^= *p++;
        for (int k = 0; k < 8; k++) {
            crc = (crc >> 1) ^ (0xEDB88320u & (0u - (crc & 1u)));
        }
    }
    return ~crc;
}

/* The checksum a header and body must carry: over the header up to its crc field, then the body. */
static uint32_t serial_crc(const SerialHeader *header, const unsigned char *body)
{
    const uint32_t crc = crc32_update(0, (const unsigned char *)header, offsetof(SerialHeader, crc));
    return crc32_update(crc, body, sizeof(Snapshot));
}

/* A serialized state holds finite numbers only: every Real slot, the times and every double of
 * the model's state (in memory a state may hold what a run reached, e.g. an overflowed observer;
 * such a state is not serialized, so nothing refused on the way in was ever written). */
static int check_finite(const Snapshot *s, char *msg)
{
    if (!isfinite(s->d.start_time) || !isfinite(s->last_time) || !isfinite(s->me_time)) {
        return fail(msg, "a time (start, last communication point or Model Exchange time) is "
                         "not finite");
    }
    for (int vr = 0; vr < N_VARS; vr++) {
        if (!isfinite(s->d.r[vr])) {
            return fail(msg, "the value of %s is not finite (%g)", VARS[vr].name, s->d.r[vr]);
        }
    }
    for (int k = 0; k < N_MODEL_STATE_REALS; k++) {
        const StateReals *f = &MODEL_STATE_REALS[k];
        for (int j = 0; j < f->count; j++) {
            double x;
            memcpy(&x, (const char *)&s->d.m + f->offset + j * sizeof x, sizeof x);
            if (!isfinite(x)) {
                return fail(msg, "%s[%d] is not finite (%g)", f->name, j, x);
            }
        }
    }
    return 0;
}

/* The header this build writes, without its checksum (crc = 0). */
static void serial_header(SerialHeader *header)
{
    memset(header, 0, sizeof *header);
    memcpy(header->magic, SERIAL_MAGIC, sizeof header->magic);
    header->n_vars = N_VARS;
    header->body_size = (uint32_t)sizeof(Snapshot);
    memcpy(header->guid, MODEL_GUID, sizeof MODEL_GUID);
}

fmi2Status instance_serialized_size(fmi2Component c, fmi2FMUstate state, size_t *size)
{
    Instance *inst = (Instance *)c;
    if (!state || !size) {
        return ERROR_FN(inst, "NULL state or size");
    }
    if (!state_ok(inst, (const StateBox *)state)) {
        return fmi2Error;
    }
    *size = sizeof(SerialHeader) + sizeof(Snapshot);
    return fmi2OK;
}

fmi2Status instance_serialize(fmi2Component c, fmi2FMUstate state, fmi2Byte serializedState[],
                                 size_t size)
{
    Instance *inst = (Instance *)c;
    const StateBox *box = (const StateBox *)state;
    SerialHeader header;
    if (!state || !serializedState || size < sizeof header + sizeof(Snapshot)) {
        return ERROR_FN(inst, "NULL state or buffer smaller than %lu bytes",
                     (unsigned long)(sizeof header + sizeof(Snapshot)));
    }
    if (!state_ok(inst, box)) {
        return fmi2Error;
    }
    if (check_finite(&box->s, inst->msg)) {
        return ERROR_FN(inst, "the state holds a number that is not finite "
                           "(%s): not serialized (it could not be restored)", inst->msg);
    }
    serial_header(&header);
    header.crc = serial_crc(&header, (const unsigned char *)&box->s);
    memcpy(serializedState, &header, sizeof header);
    memcpy(serializedState + sizeof header, &box->s, sizeof(Snapshot));
    return fmi2OK;
}

/* Bytes from outside, checked in order: big enough for a header, our magic (with a word for a
 * state of an older build), this FMU's layout and build, the exact size, the checksum; then the
 * body's fields (check_finite, check_snapshot). 0 with the body in *body, else 1 with msg set. */
static int decode_state(const unsigned char *bytes, size_t size, Snapshot *body, char *msg)
{
    const size_t expected = sizeof(SerialHeader) + sizeof(Snapshot);
    SerialHeader header, ours;
    uint32_t format1;
    if (size < sizeof header) {
        return fail(msg, "%lu bytes, not a state of this FMU (%lu bytes)", (unsigned long)size,
                    (unsigned long)expected);
    }
    memcpy(&header, bytes, sizeof header);
    memcpy(&format1, bytes, sizeof format1);
    if (format1 == SERIAL_MAGIC_FORMAT1) {
        return fail(msg, "written by an older build of a native FMU (state format 1, without a "
                         "checksum); states do not carry across builds");
    }
    if (memcmp(header.magic, SERIAL_MAGIC, sizeof header.magic) != 0) {
        return fail(msg, "not a serialized state of a native FMU (bad magic)");
    }
    serial_header(&ours);
    if (memcmp(&header, &ours, offsetof(SerialHeader, crc)) != 0) { /* every byte up to crc */
        return fail(msg, "written by another FMU or another build (this is %s, GUID %s); states "
                         "do not carry across builds", MODEL_IDENTIFIER_STR, MODEL_GUID);
    }
    if (size != expected) {
        return fail(msg, "%lu bytes, expected %lu (truncated or extended)", (unsigned long)size,
                    (unsigned long)expected);
    }
    if (serial_crc(&header, bytes + sizeof header) != header.crc) {
        return fail(msg, "checksum mismatch (the bytes are not the ones this FMU wrote)");
    }
    memcpy(body, bytes + sizeof header, sizeof *body);
    return check_finite(body, msg);
}

fmi2Status instance_deserialize(fmi2Component c, const fmi2Byte serializedState[], size_t size,
                                   fmi2FMUstate *state)
{
    Instance *inst = (Instance *)c;
    Snapshot body;
    StateBox *box;
    if (!state) {
        return ERROR_FN(inst, "the state pointer is NULL");
    }
    if (!serializedState) {
        return ERROR_FN(inst, "serialized state refused: NULL bytes");
    }
    if (decode_state((const unsigned char *)serializedState, size, &body, inst->msg) ||
        check_snapshot(&body, inst->type, inst->msg)) {
        return ERROR_FN(inst, "serialized state refused: %s", inst->msg);
    }
    box = state_for_writing(inst, state);
    if (!box) {
        return fmi2Error;
    }
    box->s = body;
    return fmi2OK;
}
