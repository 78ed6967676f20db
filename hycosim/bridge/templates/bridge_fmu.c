/*
 * hycosim bridge FMU (FMI 2.0 co-simulation), generated per node of a project JSON.
 *
 * The importing tool sets the node's outputs as this FMU's inputs and reads the node's
 * routed inputs from this FMU's outputs. Each fmi2DoStep sends the outputs for that
 * macro step to the hycosim server's TCP gateway and blocks (with a timeout) until the
 * server releases the step with the routed inputs. Framing: bridge/gateway_protocol.py
 * (version 1). No Python is needed in the importing process.
 *
 * bridge_config.h (generated) names the node, its ports and start values.
 * Builds with gcc/clang on Linux and macOS, and with MinGW on Windows (links ws2_32).
 */
#include <stdarg.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#ifdef _WIN32
#include <winsock2.h>
#include <ws2tcpip.h>
typedef SOCKET hy_socket;
#define HY_BAD_SOCKET INVALID_SOCKET
#define hy_close closesocket
#define hy_pause_100ms() Sleep(100)
#else
#include <netdb.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <sys/socket.h>
#include <sys/time.h>
#include <unistd.h>
typedef int hy_socket;
#define HY_BAD_SOCKET (-1)
#define hy_close close
#define hy_pause_100ms() do { struct timespec ts = {0, 100000000L}; nanosleep(&ts, NULL); } while (0)
#endif

#include "fmi2Functions.h"
#include "bridge_config.h"

#define HY_N_VALUES (HY_N_OUT + HY_N_IN)
#define HY_VR_SERVER (HY_N_VALUES + 0)
#define HY_VR_NODE (HY_N_VALUES + 1)
#define HY_VR_UID (HY_N_VALUES + 2)
#define HY_VR_TIMEOUT (HY_N_VALUES + 3)
#define HY_MIN_TIMEOUT 0.001 /* s; keep in step with bridge_fmu.TIMEOUT_RANGE */
#define HY_MAX_TIMEOUT 1e6
#define HY_VR_DRIVEN (HY_N_VALUES + 4) /* Boolean output: the mode of the last release */
#define HY_MAGIC "HYCO"
#define HY_PROTOCOL 1
enum { F_HELLO = 1, F_WELCOME, F_REFUSE, F_START, F_OUTPUTS, F_STEP, F_STOP };

typedef struct {
    const fmi2CallbackFunctions *cb;
    char instance[128];
    int logging;
    double values[HY_N_VALUES > 0 ? HY_N_VALUES : 1]; /* node outputs, then node inputs */
    char server[256];
    char node[128];
    int uid;
    double timeout;
    hy_socket sock;
    int started;   /* START received */
    int stopped;   /* STOP received: the co-simulation is over */
    long long step;
    double t0;
    double t_done; /* end of the last released step: a node's last step may be cut at the stop time */
    int driven;
} Bridge;

static void logf_(Bridge *b, fmi2Status status, const char *category, const char *fmt, ...) {
    char msg[512];
    va_list ap;
    if (!b || !b->cb || !b->cb->logger) return;
    if (status == fmi2OK && !b->logging) return;
    va_start(ap, fmt);
    vsnprintf(msg, sizeof msg, fmt, ap);
    va_end(ap);
    b->cb->logger(b->cb->componentEnvironment, b->instance, status, category, "%s", msg);
}

/* ---- little-endian packing --------------------------------------------------------- */

static void put_u16(unsigned char *p, uint16_t v) { p[0] = (unsigned char)v; p[1] = (unsigned char)(v >> 8); }
static void put_u32(unsigned char *p, uint32_t v) { for (int i = 0; i < 4; i++) p[i] = (unsigned char)(v >> (8 * i)); }
static void put_u64(unsigned char *p, uint64_t v) { for (int i = 0; i < 8; i++) p[i] = (unsigned char)(v >> (8 * i)); }
static uint16_t get_u16(const unsigned char *p) { return (uint16_t)(p[0] | (p[1] << 8)); }
static uint32_t get_u32(const unsigned char *p) { uint32_t v = 0; for (int i = 3; i >= 0; i--) v = (v << 8) | p[i]; return v; }
static uint64_t get_u64(const unsigned char *p) { uint64_t v = 0; for (int i = 7; i >= 0; i--) v = (v << 8) | p[i]; return v; }
static void put_f64(unsigned char *p, double d) { uint64_t v; memcpy(&v, &d, 8); put_u64(p, v); }
static double get_f64(const unsigned char *p) { uint64_t v = get_u64(p); double d; memcpy(&d, &v, 8); return d; }

/* ---- socket I/O ---------------------------------------------------------------------- */

static int send_all(hy_socket s, const unsigned char *buf, size_t n) {
    while (n > 0) {
        int sent = (int)send(s, (const char *)buf, (int)n, 0);
        if (sent <= 0) return -1;
        buf += sent;
        n -= (size_t)sent;
    }
    return 0;
}

static int recv_all(hy_socket s, unsigned char *buf, size_t n) {
    while (n > 0) {
        int got = (int)recv(s, (char *)buf, (int)n, 0);
        if (got <= 0) return -1; /* closed, error or timeout */
        buf += got;
        n -= (size_t)got;
    }
    return 0;
}

static int send_frame(Bridge *b, int type, const unsigned char *payload, uint32_t len) {
    unsigned char header[12];
    memcpy(header, HY_MAGIC, 4);
    header[4] = HY_PROTOCOL;
    header[5] = (unsigned char)type;
    put_u16(header + 6, 0);
    put_u32(header + 8, len);
    if (send_all(b->sock, header, 12) || (len && send_all(b->sock, payload, len))) return -1;
    return 0;
}

/* Reads one frame into *payload (malloc'd, caller frees); returns its type or -1. */
static int recv_frame(Bridge *b, unsigned char **payload, uint32_t *len) {
    unsigned char header[12];
    *payload = NULL;
    if (recv_all(b->sock, header, 12)) return -1;
    if (memcmp(header, HY_MAGIC, 4) != 0 || header[4] != HY_PROTOCOL) return -1;
    *len = get_u32(header + 8);
    if (*len > (1u << 20)) return -1;
    *payload = (unsigned char *)malloc(*len + 1);
    if (!*payload) return -1;
    if (*len && recv_all(b->sock, *payload, *len)) { free(*payload); *payload = NULL; return -1; }
    (*payload)[*len] = 0;
    return header[5];
}

static void set_timeout(hy_socket s, double seconds) {
#ifdef _WIN32
    DWORD ms = (DWORD)(seconds * 1000);
    setsockopt(s, SOL_SOCKET, SO_RCVTIMEO, (const char *)&ms, sizeof ms);
    setsockopt(s, SOL_SOCKET, SO_SNDTIMEO, (const char *)&ms, sizeof ms);
#else
    struct timeval tv;
    tv.tv_sec = (long)seconds;
    tv.tv_usec = (long)((seconds - (double)tv.tv_sec) * 1e6);
    setsockopt(s, SOL_SOCKET, SO_RCVTIMEO, &tv, sizeof tv);
    setsockopt(s, SOL_SOCKET, SO_SNDTIMEO, &tv, sizeof tv);
#endif
}

/* "tcp/HOST:PORT", "HOST:PORT", "[IPv6]:PORT", "HOST" or a bare IPv6 address (port 7448). */
static int connect_server(Bridge *b) {
    char host[256], port[16] = "7448";
    const char *spec = strncmp(b->server, "tcp/", 4) == 0 ? b->server + 4 : b->server;
    const char *colon = strrchr(spec, ':');
    const char *start = spec;
    struct addrinfo hints, *res = NULL, *ai;
    size_t hn;
    if (spec[0] == '[') {  /* [IPv6]:PORT or [IPv6] */
        const char *close = strchr(spec, ']');
        start = spec + 1;
        hn = close ? (size_t)(close - start) : strlen(start);
        colon = close && close[1] == ':' ? close + 1 : NULL;
    } else if (colon && strchr(spec, ':') != colon) {  /* a bare IPv6 address: no room for a port */
        hn = strlen(spec);
        colon = NULL;
    } else {
        hn = colon ? (size_t)(colon - spec) : strlen(spec);
    }
    if (hn >= sizeof host) hn = sizeof host - 1;
    memcpy(host, start, hn);
    host[hn] = 0;
    if (colon) { strncpy(port, colon + 1, sizeof port - 1); port[sizeof port - 1] = 0; }
#ifdef _WIN32
    { WSADATA wsa; WSAStartup(MAKEWORD(2, 2), &wsa); }
#endif
    memset(&hints, 0, sizeof hints);
    hints.ai_family = AF_UNSPEC;
    hints.ai_socktype = SOCK_STREAM;
    if (getaddrinfo(host, port, &hints, &res) != 0) {
        logf_(b, fmi2Error, "logStatusError", "cannot resolve hycosim server %s", b->server);
        return -1;
    }
    b->sock = HY_BAD_SOCKET;
    /* The tool may start before the server: retry until the timeout. */
    {
        time_t deadline = time(NULL) + (time_t)b->timeout + 1;
        while (b->sock == HY_BAD_SOCKET) {
            for (ai = res; ai; ai = ai->ai_next) {
                hy_socket s = socket(ai->ai_family, ai->ai_socktype, ai->ai_protocol);
                if (s == HY_BAD_SOCKET) continue;
                set_timeout(s, b->timeout);
                if (connect(s, ai->ai_addr, (int)ai->ai_addrlen) == 0) { b->sock = s; break; }
                hy_close(s);
            }
            if (b->sock != HY_BAD_SOCKET || time(NULL) >= deadline) break;
            hy_pause_100ms();
        }
    }
    freeaddrinfo(res);
    if (b->sock == HY_BAD_SOCKET) {
        logf_(b, fmi2Error, "logStatusError", "cannot connect to the hycosim gateway at %s", b->server);
        return -1;
    }
    { int one = 1; setsockopt(b->sock, IPPROTO_TCP, TCP_NODELAY, (const char *)&one, sizeof one); }
    return 0;
}

static fmi2Status attach(Bridge *b) {
    unsigned char buf[512], *reply;
    uint32_t len;
    size_t n = strlen(b->node);
    int type;
    if (connect_server(b)) return fmi2Error;
    put_u32(buf, (uint32_t)b->uid);
    put_u16(buf + 4, (uint16_t)n);
    memcpy(buf + 6, b->node, n);
    put_u16(buf + 6 + n, HY_N_OUT);
    put_u16(buf + 8 + n, HY_N_IN);
    if (send_frame(b, F_HELLO, buf, (uint32_t)(10 + n))) {
        logf_(b, fmi2Error, "logStatusError", "lost the gateway at %s while attaching", b->server);
        return fmi2Error;
    }
    type = recv_frame(b, &reply, &len);
    if (type == F_WELCOME) { free(reply); return fmi2OK; }
    logf_(b, fmi2Error, "logStatusError", "node %s (UID %d) refused by %s: %s", b->node, b->uid, b->server,
          type == F_REFUSE && reply ? (const char *)reply : "no answer");
    free(reply);
    return fmi2Error;
}

/* ---- FMI 2.0 ------------------------------------------------------------------------ */

FMI2_Export const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }
FMI2_Export const char *fmi2GetVersion(void) { return fmi2Version; }

FMI2_Export fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean on, size_t n, const fmi2String cats[]) {
    (void)n; (void)cats;
    ((Bridge *)c)->logging = on ? 1 : 0;
    return fmi2OK;
}

FMI2_Export fmi2Component fmi2Instantiate(fmi2String name, fmi2Type type, fmi2String guid, fmi2String resources,
                                          const fmi2CallbackFunctions *cb, fmi2Boolean visible, fmi2Boolean logging) {
    Bridge *b;
    (void)resources; (void)visible;
    if (!cb || type != fmi2CoSimulation || !guid || strcmp(guid, HY_GUID) != 0) return NULL;
    b = (Bridge *)calloc(1, sizeof(Bridge));
    if (!b) return NULL;
    b->cb = cb;
    strncpy(b->instance, name ? name : HY_NODE_NAME, sizeof b->instance - 1);
    b->logging = logging ? 1 : 0;
    for (int i = 0; i < HY_N_VALUES; i++) b->values[i] = HY_START[i];
    strncpy(b->server, HY_DEFAULT_SERVER, sizeof b->server - 1);
    strncpy(b->node, HY_NODE_NAME, sizeof b->node - 1);
    b->uid = HY_UID;
    b->timeout = HY_DEFAULT_TIMEOUT;
    b->sock = HY_BAD_SOCKET;
    return b;
}

FMI2_Export void fmi2FreeInstance(fmi2Component c) {
    Bridge *b = (Bridge *)c;
    if (!b) return;
    if (b->sock != HY_BAD_SOCKET) hy_close(b->sock);
    free(b);
}

FMI2_Export fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean tolDef, fmi2Real tol, fmi2Real start,
                                           fmi2Boolean stopDef, fmi2Real stop) {
    (void)c; (void)tolDef; (void)tol; (void)start; (void)stopDef; (void)stop;
    return fmi2OK;
}

FMI2_Export fmi2Status fmi2EnterInitializationMode(fmi2Component c) { (void)c; return fmi2OK; }

FMI2_Export fmi2Status fmi2ExitInitializationMode(fmi2Component c) {
    /* Parameters (server, node name, UID, timeout) are final here: attach now. */
    return attach((Bridge *)c);
}

static int send_outputs(Bridge *b, double t) {
    unsigned char out[18 + 8 * (HY_N_OUT > 0 ? HY_N_OUT : 1)];
    put_u64(out, (uint64_t)b->step);
    put_f64(out + 8, t);
    put_u16(out + 16, HY_N_OUT);
    for (int i = 0; i < HY_N_OUT; i++) put_f64(out + 18 + 8 * i, b->values[i]);
    return send_frame(b, F_OUTPUTS, out, 18 + 8 * HY_N_OUT);
}

FMI2_Export fmi2Status fmi2Terminate(fmi2Component c) {
    Bridge *b = (Bridge *)c;
    /* N doSteps report the points T_0..T_N-1; the server also wants T_N. The tool has set
       nothing newer than its last inputs, so those stand for the final point. */
    if (b->started && !b->stopped && b->sock != HY_BAD_SOCKET && send_outputs(b, b->t_done) == 0) {
        unsigned char *reply;
        uint32_t len;
        if (recv_frame(b, &reply, &len) == F_STOP) b->stopped = 1;
        free(reply);
    }
    if (b->sock != HY_BAD_SOCKET) { hy_close(b->sock); b->sock = HY_BAD_SOCKET; }
    return fmi2OK;
}

FMI2_Export fmi2Status fmi2Reset(fmi2Component c) {
    Bridge *b = (Bridge *)c;
    fmi2Terminate(c);
    for (int i = 0; i < HY_N_VALUES; i++) b->values[i] = HY_START[i];
    b->started = b->stopped = 0;
    b->step = 0;
    b->driven = 0;
    return fmi2OK;
}

static fmi2Status check_vr(Bridge *b, fmi2ValueReference vr, char type, const char *what) {
    if (vr >= HY_N_VALUES || HY_TYPES[vr] != type) {
        logf_(b, fmi2Error, "logStatusError", "%s: no %c variable with value reference %u", what, type, (unsigned)vr);
        return fmi2Error;
    }
    return fmi2OK;
}

FMI2_Export fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Real v[]) {
    Bridge *b = (Bridge *)c;
    for (size_t i = 0; i < n; i++) {
        if (vr[i] == HY_VR_TIMEOUT) { v[i] = b->timeout; continue; }
        if (check_vr(b, vr[i], 'R', "fmi2GetReal")) return fmi2Error;
        v[i] = b->values[vr[i]];
    }
    return fmi2OK;
}

FMI2_Export fmi2Status fmi2GetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Integer v[]) {
    Bridge *b = (Bridge *)c;
    for (size_t i = 0; i < n; i++) {
        if (vr[i] == HY_VR_UID) { v[i] = b->uid; continue; }
        if (check_vr(b, vr[i], 'I', "fmi2GetInteger")) return fmi2Error;
        v[i] = (fmi2Integer)b->values[vr[i]];
    }
    return fmi2OK;
}

FMI2_Export fmi2Status fmi2GetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Boolean v[]) {
    Bridge *b = (Bridge *)c;
    for (size_t i = 0; i < n; i++) {
        if (vr[i] == HY_VR_DRIVEN) { v[i] = b->driven ? fmi2True : fmi2False; continue; }
        if (check_vr(b, vr[i], 'B', "fmi2GetBoolean")) return fmi2Error;
        v[i] = b->values[vr[i]] != 0.0 ? fmi2True : fmi2False;
    }
    return fmi2OK;
}

FMI2_Export fmi2Status fmi2GetString(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2String v[]) {
    Bridge *b = (Bridge *)c;
    for (size_t i = 0; i < n; i++) {
        if (vr[i] == HY_VR_SERVER) v[i] = b->server;
        else if (vr[i] == HY_VR_NODE) v[i] = b->node;
        else { logf_(b, fmi2Error, "logStatusError", "fmi2GetString: no String variable %u", (unsigned)vr[i]); return fmi2Error; }
    }
    return fmi2OK;
}

FMI2_Export fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Real v[]) {
    Bridge *b = (Bridge *)c;
    for (size_t i = 0; i < n; i++) {
        if (vr[i] == HY_VR_TIMEOUT) {
            /* Every wait has a bound: 0 would make the socket's waits endless, NaN or 1e300 the
               deadline undefined. (Written so that NaN fails too.) */
            if (!(v[i] >= HY_MIN_TIMEOUT && v[i] <= HY_MAX_TIMEOUT)) {
                logf_(b, fmi2Error, "logStatusError", "hycosim_timeout = %g s: give %g to %g s", v[i], HY_MIN_TIMEOUT,
                      HY_MAX_TIMEOUT);
                return fmi2Error;
            }
            b->timeout = v[i];
            continue;
        }
        if (vr[i] >= HY_N_OUT || check_vr(b, vr[i], 'R', "fmi2SetReal")) {
            logf_(b, fmi2Error, "logStatusError", "fmi2SetReal: value reference %u is not an input", (unsigned)vr[i]);
            return fmi2Error;
        }
        b->values[vr[i]] = v[i];
    }
    return fmi2OK;
}

FMI2_Export fmi2Status fmi2SetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Integer v[]) {
    Bridge *b = (Bridge *)c;
    for (size_t i = 0; i < n; i++) {
        if (vr[i] == HY_VR_UID) { b->uid = v[i]; continue; }
        if (vr[i] >= HY_N_OUT || check_vr(b, vr[i], 'I', "fmi2SetInteger")) return fmi2Error;
        b->values[vr[i]] = (double)v[i];
    }
    return fmi2OK;
}

FMI2_Export fmi2Status fmi2SetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Boolean v[]) {
    Bridge *b = (Bridge *)c;
    for (size_t i = 0; i < n; i++) {
        if (vr[i] >= HY_N_OUT || check_vr(b, vr[i], 'B', "fmi2SetBoolean")) return fmi2Error;
        b->values[vr[i]] = v[i] ? 1.0 : 0.0;
    }
    return fmi2OK;
}

FMI2_Export fmi2Status fmi2SetString(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2String v[]) {
    Bridge *b = (Bridge *)c;
    for (size_t i = 0; i < n; i++) {
        char *dst = vr[i] == HY_VR_SERVER ? b->server : vr[i] == HY_VR_NODE ? b->node : NULL;
        size_t cap = vr[i] == HY_VR_SERVER ? sizeof b->server : sizeof b->node;
        if (!dst || !v[i]) { logf_(b, fmi2Error, "logStatusError", "fmi2SetString: no String parameter %u", (unsigned)vr[i]); return fmi2Error; }
        strncpy(dst, v[i], cap - 1);
        dst[cap - 1] = 0;
    }
    return fmi2OK;
}

/* The co-simulation's state lives in the server and the other nodes: no rollback here. */
FMI2_Export fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate *s) { (void)c; (void)s; return fmi2Error; }
FMI2_Export fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate s) { (void)c; (void)s; return fmi2Error; }
FMI2_Export fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate *s) { (void)c; (void)s; return fmi2Error; }
FMI2_Export fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate s, size_t *n) { (void)c; (void)s; (void)n; return fmi2Error; }
FMI2_Export fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate s, fmi2Byte b[], size_t n) { (void)c; (void)s; (void)b; (void)n; return fmi2Error; }
FMI2_Export fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte b[], size_t n, fmi2FMUstate *s) { (void)c; (void)b; (void)n; (void)s; return fmi2Error; }
FMI2_Export fmi2Status fmi2GetDirectionalDerivative(fmi2Component c, const fmi2ValueReference u[], size_t nu,
                                                    const fmi2ValueReference z[], size_t nz, const fmi2Real dv[], fmi2Real dz[]) {
    (void)c; (void)u; (void)nu; (void)z; (void)nz; (void)dv; (void)dz;
    return fmi2Error;
}
FMI2_Export fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t n,
                                                   const fmi2Integer order[], const fmi2Real v[]) {
    (void)c; (void)vr; (void)n; (void)order; (void)v;
    return fmi2Error;
}
FMI2_Export fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t n,
                                                    const fmi2Integer order[], fmi2Real v[]) {
    (void)c; (void)vr; (void)n; (void)order; (void)v;
    return fmi2Error;
}

static fmi2Status lost(Bridge *b, const char *what) {
    logf_(b, fmi2Error, "logStatusError", "node %s: %s (step %lld, gateway %s)", b->node, what, b->step, b->server);
    if (b->sock != HY_BAD_SOCKET) { hy_close(b->sock); b->sock = HY_BAD_SOCKET; }
    return fmi2Error;
}

FMI2_Export fmi2Status fmi2DoStep(fmi2Component c, fmi2Real t, fmi2Real h, fmi2Boolean noSetPrior) {
    Bridge *b = (Bridge *)c;
    unsigned char *reply;
    uint32_t len;
    int type;
    (void)noSetPrior;
    if (b->stopped) return lost(b, "the co-simulation has ended");
    if (b->sock == HY_BAD_SOCKET) return lost(b, "not attached to the server");
    if (!b->started) {
        type = recv_frame(b, &reply, &len);
        if (type == F_STOP) { b->stopped = 1; logf_(b, fmi2Warning, "logStatusWarning", "server stopped: %s", reply ? (char *)reply : ""); free(reply); return fmi2Discard; }
        if (type != F_START || len < 16) { free(reply); return lost(b, "no START from the server within the timeout"); }
        b->t0 = get_f64(reply);
        b->t_done = b->t0; /* START's H is the node's step; each release carries its own h */
        free(reply);
        b->started = 1;
    }
    /* Outputs of the node at this macro-step point... */
    if (send_outputs(b, t)) return lost(b, "lost the connection while sending outputs");
    /* ...then block until the server releases the step with the routed inputs. */
    type = recv_frame(b, &reply, &len);
    if (type == F_STOP) {
        b->stopped = 1;
        logf_(b, fmi2OK, "logAll", "server stopped the co-simulation: %s", reply ? (char *)reply : "");
        free(reply);
        return fmi2OK; /* the last point: inputs keep their values */
    }
    if (type != F_STEP || len < 27) { free(reply); return lost(b, "no release from the server within the timeout"); }
    {
        uint16_t n = get_u16(reply + 25);
        double released = get_f64(reply + 16), tol = 1e-9 * (released > 1.0 ? released : 1.0);
        if (n != HY_N_IN || len != 27u + 8u * n) { free(reply); return lost(b, "release with a wrong number of inputs"); }
        b->driven = reply[24];
        for (int i = 0; i < HY_N_IN; i++) b->values[HY_N_OUT + i] = get_f64(reply + 27 + 8 * i);
        /* The release's h, not START's H: the server cuts a node's last step at the stop time,
           as an importer stepping to the same stop time does. */
        if (h - released > tol || released - h > tol) logf_(b, fmi2Warning, "logStatusWarning", "doStep h=%g but the co-simulation step is %g", h, released);
        b->t_done = get_f64(reply + 8) + released;
    }
    free(reply);
    b->step++;
    return fmi2OK;
}

FMI2_Export fmi2Status fmi2CancelStep(fmi2Component c) { (void)c; return fmi2Error; }

FMI2_Export fmi2Status fmi2GetStatus(fmi2Component c, const fmi2StatusKind k, fmi2Status *v) { (void)c; (void)k; (void)v; return fmi2Discard; }
FMI2_Export fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind k, fmi2Real *v) {
    Bridge *b = (Bridge *)c;
    if (k == fmi2LastSuccessfulTime) { *v = b->t_done; return fmi2OK; }
    return fmi2Discard;
}
FMI2_Export fmi2Status fmi2GetIntegerStatus(fmi2Component c, const fmi2StatusKind k, fmi2Integer *v) { (void)c; (void)k; (void)v; return fmi2Discard; }
FMI2_Export fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind k, fmi2Boolean *v) {
    Bridge *b = (Bridge *)c;
    if (k == fmi2Terminated) { *v = b->stopped ? fmi2True : fmi2False; return fmi2OK; }
    return fmi2Discard;
}
FMI2_Export fmi2Status fmi2GetStringStatus(fmi2Component c, const fmi2StatusKind k, fmi2String *v) { (void)c; (void)k; (void)v; return fmi2Discard; }
