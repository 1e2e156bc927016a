/* One control period of a batch of pymunk worlds in one C call.
 *
 * sandbox/physics/stepping.py (BatchStepper) calls advance() once per control period
 * when no world of the batch has an open contact episode, with what prepare() made
 * of the live worlds' addresses (named arguments, parsed once). It makes the C calls the
 * Python path makes, in the same order and with the same arguments: Chipmunk's
 * cpSpaceEachBody with pymunk's batched set iterator on every live world's control
 * space (the commands), then for each substep the batch's clock is written and
 * cpSpaceStep is called on every live world's space, then cpSpaceEachBody with the
 * batched get iterator on every space (the state). Nothing here is linked against
 * Chipmunk or includes its headers: the functions come as addresses taken from
 * pymunk's own cffi module (ffi.addressof(lib, ...)), the spaces and the iterators'
 * data as addresses of the records pymunk and the stepper already hold.
 *
 * The clock is two doubles the Python begin callback reads (World._clock): [0] the
 * start time of the substep being stepped [s], [1] raised (nonzero) by the callback
 * when it opens a contact episode. When it is raised after a substep, advance()
 * returns at once, before the next substep and before the state is read: open
 * episodes must be updated between substeps, which the Python path then does.
 */

#include "accel.h"

/* cpSpaceStep(cpSpace *, cpFloat) with cpFloat a double, as pymunk builds Chipmunk. */
typedef void (*step_fn)(void *space, double dt);
/* cpSpaceBodyIteratorFunc: void (*)(cpBody *, void *). */
typedef void (*body_fn)(void *body, void *data);
/* cpSpaceEachBody(cpSpace *, cpSpaceBodyIteratorFunc, void *). */
typedef void (*each_fn)(void *space, body_fn func, void *data);

/* What a period of the live worlds steps: the functions, the worlds' records and
 * the clock, as prepare() was given them. */
typedef struct {
    step_fn step;
    each_fn each;
    body_fn set, get;
    void *const *spaces, *const *controls, *const *writes, *const *reads;
    Py_ssize_t count;
    int substeps;
    double *clock;
    uintptr_t write_block, read_block;
    Py_ssize_t arrays, size, num_at;
} Batch;

/* The name of prepare()'s capsules. */
#define BATCH "sandbox.physics._cstep.Batch"

/* A capsule's Batch freed with it. */
static void
free_batch(PyObject *capsule)
{
    PyMem_Free(PyCapsule_GetPointer(capsule, BATCH));
}

static void
each_body(each_fn each, body_fn func, void *const *spaces, void *const *data,
          Py_ssize_t count)
{
    for (Py_ssize_t i = 0; i < count; i++) {
        each(spaces[i], func, data[i]);
    }
}

/* The ``num`` field of ``arrays`` records of ``size`` bytes from ``block``, to 0. */
static void
clear_nums(uintptr_t block, Py_ssize_t arrays, Py_ssize_t size, Py_ssize_t num_at)
{
    for (Py_ssize_t i = 0; i < arrays; i++) {
        *(int *)(block + (uintptr_t)(i * size + num_at)) = 0;
    }
}

/* The arguments of prepare, by name (accel.h): addresses (int), then counts. */
#define PREPARE(X)                                                                 \
    X(step, INTEGER, 0)                                                            \
    X(each, INTEGER, 0)                                                            \
    X(set, INTEGER, 0)                                                             \
    X(get, INTEGER, 0)                                                             \
    X(spaces, INTEGER, 0)                                                          \
    X(controls, INTEGER, 0)                                                        \
    X(writes, INTEGER, 0)                                                          \
    X(reads, INTEGER, 0)                                                           \
    X(count, INTEGER, 0)                                                           \
    X(substeps, INTEGER, 0)                                                        \
    X(clock, INTEGER, 0)                                                           \
    X(write_arrays, INTEGER, 0)                                                    \
    X(read_arrays, INTEGER, 0)                                                     \
    X(arrays, INTEGER, 0)                                                          \
    X(size, INTEGER, 0)                                                            \
    X(num_at, INTEGER, 0)
NAMED(prepare, PREPARE)

PyDoc_STRVAR(prepare_doc,
"prepare(*, step, each, set, get, spaces, controls, writes, reads, count, substeps,\n"
"        clock, write_arrays, read_arrays, arrays, size, num_at) -> capsule\n"
"\n"
"What advance() steps, ``count`` worlds of ``substeps`` substeps a period; every\n"
"argument but the counts is an address (int), kept as given (the caller keeps\n"
"the memory they point to while it calls advance with the capsule). ``step``:\n"
"cpSpaceStep; ``each``: cpSpaceEachBody; ``set``, ``get``: pymunk's batched body\n"
"iterators; ``spaces``, ``controls``, ``writes``, ``reads``: arrays of ``count``\n"
"addresses (the worlds' spaces, control spaces and the iterators'\n"
"pmBatchedData); ``clock``: two doubles; ``write_arrays``, ``read_arrays``:\n"
"``arrays`` pmFloatArray records of ``size`` bytes, each with its int ``num`` at\n"
"byte ``num_at``.");

static PyObject *
prepare(PyObject *self, PyObject *const *args, Py_ssize_t nargs, PyObject *kwnames)
{
    prepare_args a;
    if (parse_named(&prepare_signature, args, nargs, kwnames, (Arg *)&a) < 0) {
        return NULL;
    }
    PyObject *result = NULL;
    if (a.count.n < 0 || a.substeps.n < 1 || a.substeps.n > INT32_MAX ||
        a.arrays.n < 0 || a.size.n < 1 || a.num_at.n < 0) {
        PyErr_SetString(PyExc_ValueError, "prepare: counts out of range");
        goto done;
    }
    Batch *b = PyMem_Malloc(sizeof(Batch));
    if (b == NULL) {
        PyErr_NoMemory();
        goto done;
    }
    b->step = (step_fn)(uintptr_t)a.step.n;
    b->each = (each_fn)(uintptr_t)a.each.n;
    b->set = (body_fn)(uintptr_t)a.set.n;
    b->get = (body_fn)(uintptr_t)a.get.n;
    b->spaces = (void *const *)(uintptr_t)a.spaces.n;
    b->controls = (void *const *)(uintptr_t)a.controls.n;
    b->writes = (void *const *)(uintptr_t)a.writes.n;
    b->reads = (void *const *)(uintptr_t)a.reads.n;
    b->count = a.count.n;
    b->substeps = (int)a.substeps.n;
    b->clock = (double *)(uintptr_t)a.clock.n;
    b->write_block = (uintptr_t)a.write_arrays.n;
    b->read_block = (uintptr_t)a.read_arrays.n;
    b->arrays = a.arrays.n;
    b->size = a.size.n;
    b->num_at = a.num_at.n;
    result = PyCapsule_New(b, BATCH, free_batch);
    if (result == NULL) {
        PyMem_Free(b);
    }
done:
    release_named(&prepare_signature, (Arg *)&a);
    return result;
}

PyDoc_STRVAR(advance_doc,
"advance(batch, t0, dt) -> int\n"
"\n"
"One control period of the worlds of ``batch`` (a capsule of prepare()). First\n"
"the ``num`` field of each pmFloatArray record is set to 0, and ``clock[1]`` to\n"
"0. The commands are written (``each`` with ``set`` on every control space), then\n"
"substep s starts at ``t0 + s * dt``, computed as Python computes it: the clock's\n"
"``[0]`` written and every space stepped by ``dt``. Returns the substeps stepped:\n"
"``substeps``, the state read (``each`` with ``get``), unless ``clock[1]`` was\n"
"raised after one (then the substeps stepped so far, the state not read).");

static PyObject *
advance(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    if (nargs != 3) {
        PyErr_SetString(PyExc_TypeError, "advance takes 3 arguments");
        return NULL;
    }
    Batch *b = PyCapsule_GetPointer(args[0], BATCH);
    double t0 = PyFloat_AsDouble(args[1]);
    double dt = PyFloat_AsDouble(args[2]);
    if (b == NULL || PyErr_Occurred()) {
        return NULL;
    }
    double *clock = b->clock;
    clear_nums(b->write_block, b->arrays, b->size, b->num_at);
    clear_nums(b->read_block, b->arrays, b->size, b->num_at);
    clock[1] = 0.0;
    each_body(b->each, b->set, b->controls, b->writes, b->count);
    for (int s = 0; s < b->substeps; s++) {
        /* t0 + s * dt rounded after each operation, as Python does: the volatile
           product cannot be fused with the sum into one multiply-add. */
        volatile double offset = (double)s * dt;
        clock[0] = t0 + offset;
        for (Py_ssize_t i = 0; i < b->count; i++) {
            b->step(b->spaces[i], dt);
        }
        if (clock[1] != 0.0) {
            return PyLong_FromLong(s + 1);
        }
    }
    each_body(b->each, b->get, b->spaces, b->reads, b->count);
    return PyLong_FromLong(b->substeps);
}

static PyMethodDef methods[] = {
    {"prepare", (PyCFunction)(void (*)(void))prepare, METH_FASTCALL | METH_KEYWORDS,
     prepare_doc},
    {"advance", (PyCFunction)(void (*)(void))advance, METH_FASTCALL, advance_doc},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {
    PyModuleDef_HEAD_INIT,
    "_cstep",
    "One control period of a batch of pymunk worlds in one C call "
    "(see sandbox.physics.stepping).",
    -1,
    methods,
};

PyMODINIT_FUNC
PyInit__cstep(void)
{
    return PyModule_Create(&module);
}
